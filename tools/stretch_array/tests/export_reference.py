#!/usr/bin/python3
"""Writes fixtures for a C++ test of the stretch array's ONNX regressors (OpenCV DNN): dnn, lr and
svm briefly trained (--tiny) on a small synthetic dataset by train.py, fixed inputs, and the outputs
PyTorch's *training* form gives for them (so the comparison covers the export's folding too).

  /usr/bin/python3 tools/stretch_array/tests/export_reference.py --out build/dev/tests/array_model_fresh

Writes into --out:
  dnn/model.onnx dnn/model.json, lr/..., svm/...   the models and sidecars (as train.py writes them)
  inputs.npy         float32 [K, C]    raw C/C0 ratios: real frames, random ratios, all-rest (1.0)
  dnn_output.npy     float32 [K, 3M]   metres, marker-major; likewise lr_output.npy, svm_output.npy
  wrong_shape.onnx   "cells" [1, C] -> "markers" [1, 3M + 3] (a loader must refuse it against the sidecar)
OpenCV 4.6 agreed with these outputs to 3e-6 m when this was written. Deterministic for a seed
and torch build (one thread).
"""

import argparse
import os
import shutil
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

import array_dataset as ads  # noqa: E402
import regressors  # noqa: E402
import synthetic  # noqa: E402
import train  # noqa: E402

CELLS, MARKERS = 24, 6


def fixed_inputs(data, seed):
    rng = np.random.default_rng(seed)
    real = data.cells[np.sort(rng.choice(len(data.cells), size=8, replace=False))]
    random_ratios = rng.uniform(0.7, 2.2, size=(4, CELLS))
    rest = np.ones((1, CELLS))
    return np.concatenate([real, random_ratios, rest]).astype(np.float32)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="fixture directory to write")
    p.add_argument("--seed", type=int, default=7)
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    data_dir = os.path.join(a.out, "synthetic_data")
    try:
        synthetic.generate(data_dir, cells=CELLS, markers=MARKERS, sessions=(("train", 0, 600), ("test", 0, 100)),
                           seed=a.seed)
        data = ads.ArrayDataset(data_dir)
        inputs = fixed_inputs(data, a.seed)
        np.save(os.path.join(a.out, "inputs.npy"), inputs)
        for kind in regressors.KINDS:
            out = os.path.join(a.out, kind)
            rc = train.main([data_dir, "--model", kind, "--tiny", "--epochs", "5", "--max-centres", "200",
                             "--seed", str(a.seed), "--threads", "1", "--quiet", "--out", out])
            if rc != 0:
                return rc
            model, _ = train.load(out)
            with torch.no_grad():
                reference = model(torch.from_numpy(inputs)).numpy().astype(np.float32)
            np.save(os.path.join(a.out, f"{kind}_output.npy"), reference)
            os.remove(os.path.join(out, "model.pt"))
        wrong = torch.nn.Linear(CELLS, 3 * MARKERS + 3).eval()
        torch.onnx.export(wrong, torch.ones(1, CELLS), os.path.join(a.out, "wrong_shape.onnx"),
                          opset_version=train.OPSET, input_names=["cells"], output_names=["markers"])
    finally:
        shutil.rmtree(data_dir, ignore_errors=True)
    print(f"wrote fixtures to {a.out}: {len(inputs)} inputs, {', '.join(regressors.KINDS)}, torch {torch.__version__}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
