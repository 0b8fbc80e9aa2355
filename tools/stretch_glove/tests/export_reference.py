#!/usr/bin/python3
"""Writes the fixtures for the C++ OnnxPoseModel tests: a U-Net and an FCN,
briefly trained on a small synthetic dataset (so BatchNorm statistics and
weights are not trivial) and exported by train.py, plus fixed inputs and
PyTorch's outputs for them, computed by the *training* model (not the exported
inference form), so the C++ comparison covers the export rewrites too.

  /usr/bin/python3 tools/stretch_glove/tests/export_reference.py --out tests/data/stretch_model

Writes into --out:
  unet.onnx unet.json fcn.onnx fcn.json   the models and their sidecars
  inputs.npy          float32 [K, 2, 5, 5]  fixed network inputs
  unet_output.npy     float32 [K, 1, 5, 5]  PyTorch's outputs (radians)
  fcn_output.npy      float32 [K, 1, 5, 5]
  wrong_shape.onnx    a network with output [B, 3, 5, 5] (the loader must refuse it)
Deterministic for a given seed and torch build (one thread).
"""

import argparse
import os
import shutil
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

# Before numpy/torch load an OpenMP runtime: see training.py.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

import dataset as ds  # noqa: E402
import synthetic  # noqa: E402
import train  # noqa: E402
import training  # noqa: E402


def fixed_inputs(data, seed):
    """Real normalised frames, random grids, and the corners of the input range."""
    rng = np.random.default_rng(seed)
    frames = data.frames(range(len(data.sessions)), phase=1)
    pick = np.sort(rng.choice(frames, size=8, replace=False))
    real = data.inputs(pick)
    occupied = np.zeros(ds.INPUT_SLOTS, dtype=np.float32)
    occupied[data.input_grid_index] = 1.0
    random_cells = rng.uniform(-2.0, 2.0, size=(6, ds.INPUT_SLOTS)).astype(np.float32) * occupied
    corners = np.stack([np.zeros(ds.INPUT_SLOTS, np.float32), occupied * 2.0, occupied * -2.0,
                        occupied * np.where(np.arange(ds.INPUT_SLOTS) % 2 == 0, 1.0, -1.0).astype(np.float32)])
    extra = np.concatenate([random_cells, corners]).reshape(-1, 2, 5, 5)
    return np.concatenate([real, extra]).astype(np.float32)


def write_wrong_shape_model(path):
    wrong = torch.nn.Conv2d(2, 3, 1).eval()
    torch.onnx.export(wrong, torch.zeros(1, 2, 5, 5), path, opset_version=training.DEFAULT_OPSET,
                      input_names=[training.INPUT_NAME], output_names=[training.OUTPUT_NAME])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="fixture directory to write")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--epochs", type=int, default=2, help="training epochs per model (default 2)")
    p.add_argument("--unet-width", type=int, default=16)
    p.add_argument("--fcn-hidden", default="384,384,384,192")
    p.add_argument("--keep-pt", action="store_true", help="keep the .pt weights (not needed by the C++ tests)")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    # A fixed scratch path, so the sidecars (which name their data) come out the same every time.
    data_dir = os.path.join(a.out, "synthetic_data")
    try:
        synthetic.generate(data_dir, subjects=2, sessions=1, minutes=0.25, exploration_seconds=5.0, seed=a.seed)
        data = ds.Dataset(data_dir)
        inputs = fixed_inputs(data, a.seed)
        np.save(os.path.join(a.out, "inputs.npy"), inputs)
        for kind in ("unet", "fcn"):
            onnx_path = os.path.join(a.out, f"{kind}.onnx")
            rc = train.main(["--data", data_dir, "--model", kind, "--epochs", str(a.epochs), "--seed", str(a.seed),
                             "--threads", "1", "--quiet", "--unet-width", str(a.unet_width),
                             "--fcn-hidden", a.fcn_hidden, "--out", onnx_path])
            if rc != 0:
                return rc
            pt_path = os.path.join(a.out, f"{kind}.pt")
            model, _ = training.load_checkpoint(pt_path)
            with torch.no_grad():
                reference = model(torch.from_numpy(inputs)).numpy().astype(np.float32)
            np.save(os.path.join(a.out, f"{kind}_output.npy"), reference)
            if not a.keep_pt:
                os.remove(pt_path)
        write_wrong_shape_model(os.path.join(a.out, "wrong_shape.onnx"))
    finally:
        shutil.rmtree(data_dir, ignore_errors=True)
    print(f"wrote fixtures to {a.out}: {inputs.shape[0]} inputs, unet + fcn, torch {torch.__version__}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
