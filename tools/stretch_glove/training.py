#!/usr/bin/python3
"""The training loop, metrics, ONNX export and model files shared by train.py,
finetune.py and evaluate.py.

A trained model is three files with one stem:
  NAME.onnx  the network for OpenCV DNN: input "stretch" [1,2,5,5], output "pose" [1,1,5,5]
  NAME.json  sidecar: layout and grids, normalisation, model kind, seed, training summary,
             validation error; the C++ OnnxPoseModel checks it against the glove layout
  NAME.pt    PyTorch weights + the sidecar, for fine-tuning
"""

import copy
import json
import math
import os
import platform
import sys
import time
import zlib

# libgomp's default busy-waiting makes 2 threads 30x slower than 1 on a
# machine whose cores are also busy (measured on the 2-core dev VM); passive
# waiting costs nothing when the cores are free. Must be set before torch loads.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

import models  # noqa: E402

SIDECAR_FORMAT = "proprio-stretch-pose-model"
SIDECAR_VERSION = 1
INPUT_NAME = "stretch"
OUTPUT_NAME = "pose"
DEFAULT_OPSET = 11
NORMALISATION_FORMULA = "x = 2 (c - min) / (max - min) - 1, clamped to [-2, 2]"


def configure_torch(threads, seed):
    """Deterministic CPU training: same seed, same thread count, same torch build -> same weights."""
    if threads < 1:
        raise ValueError(f"--threads must be >= 1, got {threads}")
    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True)
    np.random.seed(seed % (2**32))


def stem_paths(onnx_path):
    if not onnx_path.endswith(".onnx"):
        raise ValueError(f"output '{onnx_path}' must end in .onnx (the sidecar .json and weights .pt go next to it)")
    stem = onnx_path[: -len(".onnx")]
    return {"onnx": onnx_path, "json": stem + ".json", "pt": stem + ".pt"}


class TrainConfig:
    def __init__(self, epochs=60, batch=256, lr=2e-4, optimizer="adam", betas=(0.5, 0.999), weight_decay=0.0,
                 patience=8, seed=1, threads=2, min_delta_deg=1e-3, freeze_batchnorm=False):
        self.epochs = int(epochs)
        self.batch = int(batch)
        self.lr = float(lr)
        self.optimizer = optimizer
        self.betas = tuple(betas)
        self.weight_decay = float(weight_decay)
        self.patience = int(patience)
        self.seed = int(seed)
        self.threads = int(threads)
        self.min_delta_deg = float(min_delta_deg)
        # Keep BatchNorm's running statistics (and use them in training) instead
        # of re-estimating them from the new data: for fine-tuning on one short session.
        self.freeze_batchnorm = bool(freeze_batchnorm)
        if self.epochs < 1 or self.batch < 2 or self.lr <= 0 or self.patience < 1:
            raise ValueError("epochs >= 1, batch >= 2, lr > 0 and patience >= 1 are required")
        if optimizer not in ("adam", "sgd"):
            raise ValueError(f"optimizer '{optimizer}': expected adam or sgd")

    def as_dict(self):
        return {"epochs": self.epochs, "batch": self.batch, "lr": self.lr, "optimizer": self.optimizer,
                "betas": list(self.betas), "weight_decay": self.weight_decay, "patience": self.patience,
                "seed": self.seed, "threads": self.threads, "freeze_batchnorm": self.freeze_batchnorm}


def output_range_from_targets(y, mask, margin=0.15):
    """Per output cell: the tanh's centre and half range, covering the training
    angles widened by `margin` of their span on each side (empty cells: 0)."""
    flat = y.reshape(y.shape[0], -1)
    lo = flat.min(axis=0)
    hi = flat.max(axis=0)
    span = np.maximum(hi - lo, np.float32(0.1))
    centre = np.where(mask, 0.5 * (lo + hi), 0.0).astype(np.float32)
    half = np.where(mask, 0.5 * span * (1.0 + 2.0 * margin), 0.0).astype(np.float32)
    return torch.from_numpy(centre), torch.from_numpy(half)


def masked_mse(pred, target, mask_t):
    diff = (pred - target).reshape(pred.shape[0], -1)[:, mask_t]
    return (diff * diff).mean()


def predict(model, x, batch=8192):
    model.eval()
    out = []
    with torch.no_grad():
        for i in range(0, len(x), batch):
            out.append(model(torch.from_numpy(np.ascontiguousarray(x[i:i + batch]))).numpy())
    return np.concatenate(out) if out else np.zeros((0, 1, models.GRID, models.GRID), np.float32)


def angle_errors_deg(pred, target, output_grid):
    """Mean absolute joint-angle error, per DoF and over all DoFs, in degrees."""
    p = pred.reshape(pred.shape[0], -1)
    t = target.reshape(target.shape[0], -1)
    per_dof = {}
    for k, name in enumerate(output_grid):
        if name is not None:
            per_dof[name] = float(np.degrees(np.mean(np.abs(p[:, k] - t[:, k]))))
    mean = float(np.mean(list(per_dof.values()))) if per_dof else float("nan")
    return {"mean_deg": mean, "per_dof_deg": per_dof}


def _make_optimizer(model, cfg):
    if cfg.optimizer == "adam":
        return torch.optim.Adam(model.parameters(), lr=cfg.lr, betas=cfg.betas, weight_decay=cfg.weight_decay)
    return torch.optim.SGD(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)


def fit(model, train_x, train_y, val_x, val_y, mask, cfg, output_grid, log=print, label=""):
    """Minibatch training with early stopping on the validation mean angle error.

    Returns a summary dict; the model is left with its best-validation weights.
    Without validation frames, the last epoch's weights are kept.
    """
    start = time.time()
    mask_t = torch.from_numpy(np.asarray(mask, dtype=bool))
    x = torch.from_numpy(np.ascontiguousarray(train_x))
    y = torch.from_numpy(np.ascontiguousarray(train_y))
    n = x.shape[0]
    if n < 2:
        raise ValueError(f"{n} training frames: need at least 2")
    batch = min(cfg.batch, n)
    generator = torch.Generator().manual_seed(cfg.seed)
    optimizer = _make_optimizer(model, cfg)
    has_val = val_x is not None and len(val_x) > 0
    best = {"val_deg": math.inf, "epoch": 0, "state": copy.deepcopy(model.state_dict())}
    history = []
    stale = 0
    prefix = f"[{label}] " if label else ""
    for epoch in range(1, cfg.epochs + 1):
        t0 = time.time()
        model.train()
        if cfg.freeze_batchnorm:
            for m in model.modules():
                if isinstance(m, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)):
                    m.eval()
        order = torch.randperm(n, generator=generator)
        total, batches = 0.0, 0
        for i in range(0, n, batch):
            idx = order[i:i + batch]
            if len(idx) < 2:  # BatchNorm needs two samples in training mode
                continue
            optimizer.zero_grad(set_to_none=True)
            loss = masked_mse(model(x[idx]), y[idx], mask_t)
            loss.backward()
            optimizer.step()
            total += float(loss)
            batches += 1
        train_loss = total / max(batches, 1)
        entry = {"epoch": epoch, "train_mse_rad2": train_loss, "seconds": time.time() - t0}
        if has_val:
            val = angle_errors_deg(predict(model, val_x), val_y, output_grid)["mean_deg"]
            entry["val_deg"] = val
            if val < best["val_deg"] - cfg.min_delta_deg:
                best = {"val_deg": val, "epoch": epoch, "state": copy.deepcopy(model.state_dict())}
                stale = 0
            else:
                stale += 1
        history.append(entry)
        if log:
            msg = f"{prefix}epoch {epoch}/{cfg.epochs}: train {math.degrees(math.sqrt(max(train_loss, 0))):.2f} deg rms"
            if has_val:
                msg += f", validation {entry['val_deg']:.2f} deg mean (best {best['val_deg']:.2f} @ {best['epoch']})"
            msg += f", {entry['seconds']:.1f} s"
            log(msg)
        if has_val and stale >= cfg.patience:
            if log:
                log(f"{prefix}early stop: no validation improvement for {cfg.patience} epochs")
            break
    if has_val:
        model.load_state_dict(best["state"])
    model.eval()
    return {"epochs_run": len(history), "best_epoch": best["epoch"] if has_val else len(history),
            "best_val_deg": best["val_deg"] if has_val else None, "seconds": time.time() - start,
            "seconds_per_epoch": (time.time() - start) / max(len(history), 1), "train_frames": int(n),
            "val_frames": int(len(val_x)) if has_val else 0, "history": history}


def export_onnx(model, path, opset=DEFAULT_OPSET):
    """Writes the inference form (BatchNorm folded), batch 1, and checks that it
    computes what the trained model computes."""
    model.eval()
    inference = models.inference_form(model)
    probe = torch.from_numpy(np.random.default_rng(0).uniform(-2, 2, size=(16, 2, 5, 5)).astype(np.float32))
    with torch.no_grad():
        gap = float((inference(probe) - model(probe)).abs().max())
    if gap > 1e-4:
        raise RuntimeError(f"inference form differs from the trained model by {gap:g} (a bug in models.inference_form)")
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    # Batch 1, fixed: the C++ runs one frame per call, and an OpenCV 4.6 Net must
    # not see a second input shape anyway (docs/platform-notes.md). Fixed shapes
    # also let every tensor shape in the file be known.
    torch.onnx.export(inference, torch.zeros(1, 2, models.GRID, models.GRID), path, opset_version=opset,
                      input_names=[INPUT_NAME], output_names=[OUTPUT_NAME], do_constant_folding=True)
    return gap


def build_sidecar(dataset, model, *, calibration, global_min=None, global_max=None, seed, training, validation,
                  data_summary, opset=DEFAULT_OPSET, extra=None):
    sidecar = {
        "format": SIDECAR_FORMAT,
        "format_version": SIDECAR_VERSION,
        "layout": dataset.layout_name,
        "cell_count": dataset.cell_count,
        "input_grid_index": [int(i) for i in dataset.input_grid_index],
        "output_grid": dataset.output_grid,
        "dof_names": dataset.dof_names,
        "input": {"name": INPUT_NAME, "shape": [1, 2, models.GRID, models.GRID], "dtype": "float32"},
        "output": {"name": OUTPUT_NAME, "shape": [1, 1, models.GRID, models.GRID], "dtype": "float32",
                   "units": "rad"},
        "normalisation": {"formula": NORMALISATION_FORMULA, "calibration": calibration},
        "model": dict(models.model_config(model), parameters=models.parameter_count(model)),
        "seed": int(seed),
        "training": dict(training, data=data_summary),
        "validation": validation,
        "torch_version": torch.__version__,
        "python_version": platform.python_version(),
        "opset": opset,
        "command": " ".join(sys.argv),
    }
    if calibration == "global":
        sidecar["normalisation"]["global_min_pf"] = [float(v) for v in global_min]
        sidecar["normalisation"]["global_max_pf"] = [float(v) for v in global_max]
    if extra:
        sidecar.update(extra)
    return sidecar


def save_model(model, onnx_path, sidecar, opset=DEFAULT_OPSET):
    paths = stem_paths(onnx_path)
    export_onnx(model, paths["onnx"], opset)
    with open(paths["onnx"], "rb") as f:
        onnx_bytes = f.read()
    # The C++ loader refuses an .onnx whose bytes no longer match (damaged
    # weights can still parse).
    sidecar = dict(sidecar, onnx_crc32=zlib.crc32(onnx_bytes), onnx_bytes=len(onnx_bytes))
    with open(paths["json"], "w", encoding="utf-8") as f:
        json.dump(sidecar, f, indent=1)
        f.write("\n")
    torch.save({"config": models.model_config(model), "state_dict": model.state_dict(), "sidecar": sidecar},
               paths["pt"])
    return paths


def load_checkpoint(pt_path):
    if not os.path.exists(pt_path):
        raise FileNotFoundError(f"{pt_path}: no such file (train.py writes NAME.pt next to NAME.onnx)")
    try:
        blob = torch.load(pt_path, map_location="cpu")
        model = models.build_from_config(blob["config"])
        model.load_state_dict(blob["state_dict"])
    except (KeyError, RuntimeError, EOFError, ValueError) as e:
        raise ValueError(f"{pt_path}: not a stretch-glove checkpoint written by train.py ({e})") from e
    model.eval()
    return model, blob.get("sidecar", {})


def check_compatible(sidecar, dataset, where):
    """A model only fits data on the same grids."""
    if list(sidecar.get("input_grid_index", [])) != [int(i) for i in dataset.input_grid_index]:
        raise ValueError(f"{where}: the model's input_grid_index differs from the dataset's (another glove layout)")
    if list(sidecar.get("output_grid", [])) != dataset.output_grid:
        raise ValueError(f"{where}: the model's output_grid differs from the dataset's")


def parse_int_list(text, what):
    if text is None or text == "":
        return None
    try:
        return [int(v) for v in str(text).split(",") if v.strip() != ""]
    except ValueError:
        raise ValueError(f"{what} '{text}': expected comma-separated integers, e.g. 0,2,5") from None
