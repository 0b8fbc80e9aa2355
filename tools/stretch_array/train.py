#!/usr/bin/python3
"""Trains a stretch-array regressor (cells' C/C0 -> marker positions) and writes
DIR/model.onnx (input "cells" [1, C], output "markers" [1, 3M] metres marker-major, normalisation
inside), DIR/model.json (sidecar) and DIR/model.pt (PyTorch form, for evaluate.py).

  /usr/bin/python3 tools/stretch_array/train.py DATASET --model dnn --out DIR
  /usr/bin/python3 tools/stretch_array/train.py DATASET --model svm --out DIR --pose-keep "alpha<20 or alpha>40"

--model dnn is Fig. 4.13 (thesis sizes; --tiny: widths 64-64-64-32, 40 epochs, lr 1e-3, batch 64,
for CI); lr is ridge least squares; svm is RBF kernel ridge regression (see regressors.py).
Training sessions default to split=train, test sessions to split=test; the last --val-fraction of
each training session (contiguous) is held out for early stopping and hyper-parameters.
"""

import argparse
import json
import os
import platform
import sys
import time
import zlib

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # see tools/stretch_glove/training.py

import torch  # noqa: E402

import array_dataset as ads  # noqa: E402
import regressors  # noqa: E402

SIDECAR_FORMAT = "proprio-stretch-array-regressor"
SIDECAR_VERSION = 1
OPSET = 11
onnx_info = ads.load_glove_module("onnx_info")


def add_options(p):
    p.add_argument("--tiny", action="store_true", help="CI-sized DNN (widths 64, 40 epochs, lr 1e-3, batch 64)")
    p.add_argument("--epochs", type=int, help="DNN maximum epochs (default 200; --tiny 40)")
    p.add_argument("--batch", type=int, help="DNN minibatch (default 256; --tiny 64)")
    p.add_argument("--lr", type=float, help="DNN Adam learning rate (default 1e-4; --tiny 1e-3)")
    p.add_argument("--lambda", dest="weight_lambda", type=float, default=1e-5,
                   help="DNN weight regularisation of eq. 4.9 (default 1e-5)")
    p.add_argument("--patience", type=int, help="DNN early-stopping patience in epochs (default 10)")
    p.add_argument("--hidden", help="DNN hidden widths, comma-separated (default 2048,2048,2048,1024)")
    p.add_argument("--val-fraction", type=float, default=0.1,
                   help="tail of each training session held out for validation (default 0.1)")
    p.add_argument("--max-centres", type=int, default=1000, help="svm: most kernel centres (default 1000)")
    p.add_argument("--ridge", type=float, default=1e-6, help="lr: ridge, relative to frame count (default 1e-6)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads (default 2)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def dnn_config(a):
    hidden = None
    if a.hidden:
        try:
            hidden = tuple(int(v) for v in a.hidden.split(","))
        except ValueError:
            raise ValueError(f"--hidden '{a.hidden}': expected comma-separated integers") from None
    over = dict(epochs=a.epochs, batch=a.batch, lr=a.lr, patience=a.patience, hidden=hidden, seed=a.seed,
                threads=a.threads, weight_lambda=a.weight_lambda)
    if a.tiny:
        return regressors.DnnConfig.tiny(**over)
    return regressors.DnnConfig(**{k: v for k, v in over.items() if v is not None})


def training_frames(data, train_sessions, pose_keep, val_fraction):
    """(train frames, validation frames) of the chosen sessions, pose filter applied to both."""
    if not 0.0 <= val_fraction < 0.9:
        raise ValueError(f"--val-fraction {val_fraction}: expected 0 <= f < 0.9")
    frames = data.frames(train_sessions)
    if pose_keep:
        frames = frames[ads.pose_filter(pose_keep, data.pose_name)(data.pose[frames])]
    if len(frames) < 4:
        raise ValueError(f"{len(frames)} training frames after session selection and --pose-keep: too few")
    return ads.validation_split(data, frames, val_fraction)


def train(data, kind, train_sessions, a, pose_keep=None, log=None):
    """Returns (model, info, train frames, validation frames)."""
    train_f, val_f = training_frames(data, train_sessions, pose_keep, a.val_fraction)
    x, y = data.cells[train_f], data.targets(train_f)
    xv, yv = data.cells[val_f], data.targets(val_f)
    cfg = dnn_config(a)
    torch.set_num_threads(cfg.threads)
    if log:
        log(f"{kind}: {len(train_f)} training and {len(val_f)} validation frames from sessions {train_sessions}"
            + (f", pose kept where {pose_keep}" if pose_keep else ""))
    model, info = regressors.fit(kind, x, y, xv, yv, data.marker_count, dnn_config=cfg, lr_ridge=a.ridge,
                                 max_centres=a.max_centres, seed=a.seed, log=log)
    if kind == "dnn":
        info["config"] = cfg.as_dict()
    return model, info, train_f, val_f


def test_errors(data, model, sessions):
    """Marker error statistics (mm) on these sessions, against the true and the labelled markers."""
    frames = data.frames(sessions)
    pred = regressors.predict(model, data.cells[frames])
    m = data.marker_count
    return {"sessions": [int(s) for s in sessions], "frames": int(len(frames)),
            "truth": ads.error_stats_mm(ads.marker_errors_m(pred, data.targets(frames, truth=True), m)),
            "labelled": ads.error_stats_mm(ads.marker_errors_m(pred, data.targets(frames), m))}


def save(out_dir, model, sidecar):
    """model.onnx, model.json (with the ONNX file's ops and CRC), model.pt."""
    os.makedirs(out_dir, exist_ok=True)
    onnx_path = os.path.join(out_dir, "model.onnx")
    gap = regressors.export_onnx(model, onnx_path, OPSET)
    with open(onnx_path, "rb") as f:
        blob = f.read()
    outline = onnx_info.read(onnx_path)
    sidecar = dict(sidecar, onnx_ops=sorted(set(outline["ops"])), onnx_bytes=len(blob), onnx_crc32=zlib.crc32(blob),
                   onnx_inference_gap_m=gap, opset=OPSET)
    with open(os.path.join(out_dir, "model.json"), "w", encoding="utf-8") as f:
        json.dump(sidecar, f, indent=1)
        f.write("\n")
    torch.save({"config": model.config(), "state_dict": model.state_dict(), "sidecar": sidecar},
               os.path.join(out_dir, "model.pt"))
    return sidecar


def load(model_dir):
    """(torch model, sidecar) from a directory written by train.py."""
    path = os.path.join(model_dir, "model.pt")
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path}: no such file (train.py --out DIR writes DIR/model.pt)")
    try:
        blob = torch.load(path, map_location="cpu")
        model = regressors.build_from_config(blob["config"])
        model.load_state_dict(blob["state_dict"])
    except (KeyError, RuntimeError, EOFError, ValueError) as e:
        raise ValueError(f"{path}: not a stretch-array model written by train.py ({e})") from e
    return model.eval(), blob.get("sidecar", {})


def sidecar_for(data, kind, model, info, train_sessions, train_f, val_f, pose_keep, test=None):
    return {
        "format": SIDECAR_FORMAT, "format_version": SIDECAR_VERSION,
        "cell_count": data.cell_count, "marker_count": data.marker_count, "kind": kind,
        "layout": data.layout_name, "trained_on": data.summary(train_sessions),
        "epochs": info.get("epochs_run", 0), "train_frames": int(len(train_f)), "val_frames": int(len(val_f)),
        "val_error_mm": info.get("val_error_mm"),
        "cell_names": data.meta.get("cell_names"), "marker_names": data.meta.get("marker_names"),
        "input": {"name": "cells", "shape": [1, data.cell_count], "dtype": "float32", "units": "C/C0"},
        "output": {"name": "markers", "shape": [1, 3 * data.marker_count], "dtype": "float32", "units": "m",
                   "order": "marker-major x y z"},
        "normalisation": "inside the graph (no preprocessing: feed raw C/C0 ratios)",
        "pose_keep": pose_keep, "dataset": os.path.abspath(data.directory), "motion": data.motion,
        "training": {k: v for k, v in info.items() if k != "history"},
        "test": test, "torch_version": torch.__version__, "python_version": platform.python_version(),
        "command": " ".join(sys.argv),
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", help="dataset directory (proprio sim-array)")
    p.add_argument("--model", choices=regressors.KINDS, default="dnn")
    p.add_argument("--out", required=True, help="output directory (model.onnx, model.json, model.pt)")
    p.add_argument("--train-sessions", default="split=train", help="training sessions: " + ads.SELECTOR_HELP)
    p.add_argument("--test-sessions", default="split=test",
                   help="sessions whose error is reported after training (default split=test; 'none' to skip)")
    p.add_argument("--pose-keep", help="keep only training frames whose pose satisfies this, e.g. "
                                       "\"alpha<20 or alpha>40\" (Table 4.2)")
    add_options(p)
    a = p.parse_args(argv)
    log = (lambda *_: None) if a.quiet else (lambda msg: print(msg, flush=True))
    started = time.time()
    try:
        data = ads.ArrayDataset(a.dataset)
        train_s = ads.select_sessions(data, a.train_sessions)
        if not train_s:
            raise ValueError(f"--train-sessions '{a.train_sessions}' selects no session")
        test_s = [] if a.test_sessions == "none" else ads.select_sessions(data, a.test_sessions)
        if a.pose_keep:
            ads.pose_filter(a.pose_keep, data.pose_name)  # refuse a bad expression before training
        model, info, train_f, val_f = train(data, a.model, train_s, a, a.pose_keep, log)
    except (ValueError, ads.DatasetError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    test = test_errors(data, model, test_s) if test_s else None
    sidecar = save(a.out, model, sidecar_for(data, a.model, model, info, train_s, train_f, val_f, a.pose_keep, test))
    msg = (f"wrote {os.path.join(a.out, 'model.onnx')} (+ model.json, model.pt): {a.model}, "
           f"{info['parameters']} parameters, {len(train_f)} training frames, {time.time() - started:.1f} s")
    if info.get("val_error_mm") is not None:
        msg += f"; validation {info['val_error_mm']:.2f} mm"
    if test:
        t = test["truth"]
        msg += f"; test ({test['frames']} frames) mean {t['mean']:.2f} std {t['std']:.2f} max {t['max']:.2f} mm"
    print(msg + f"; ONNX ops {','.join(sidecar['onnx_ops'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
