#!/usr/bin/python3
"""The stretch array's regressors (Glauser 2019, Sec. 4.4.2 and Table 4.1): capacitance
ratios C/C0 of the cells -> marker positions. Three kinds, one interface:

  dnn  Fig. 4.13: a linear input layer (cell_count -> input_width, default cell_count, our
       reading of "takes s sensor cell capacitance readings as inputs of a linear layer"),
       3 x FC 2048, FC 1024, linear output 3M; ReLU then BatchNorm after the input and every
       hidden layer. Loss eq. 4.9 (squared marker error + lambda ||theta||^2, lambda 1e-5),
       Adam lr 1e-4, batch 256, inputs standardised (zero mean, unit variance) and targets
       standardised too (undone inside the model). Early stopping on a validation slice.
  lr   linear least squares on the standardised inputs with a small ridge (1e-6 relative).
  svm  the thesis's "non-linear SVM with an RBF kernel" stand-in: KERNEL RIDGE regression with
       a Gaussian RBF kernel (not an epsilon-SVR: squared loss, closed-form solve), using at most
       `max_centres` training frames as kernel centres (subset-of-regressors: minimise
       ||K_nz a - y||^2 + lambda a^T K_zz a); gamma (median heuristic times a factor) and lambda
       chosen on the validation slice.

Every model's inference form takes "cells" float [1, C] (raw ratios: the input standardisation
is folded into the first layer) and gives "markers" float [1, 3M], metres, marker-major
(x0 y0 z0 x1 ...), so the C++ side needs no statistics. ONNX ops: dnn and lr use Gemm and
Relu only (BatchNorm folded into the next Gemm); svm uses Gemm, Mul, MatMul, Add, Exp.
"""

import copy
import math
import os
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # see tools/stretch_glove/training.py

import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch import nn  # noqa: E402

KINDS = ("dnn", "lr", "svm")
THESIS_HIDDEN = (2048, 2048, 2048, 1024)
TINY_HIDDEN = (64, 64, 64, 32)


class Standardiser:
    """Per-column mean and standard deviation (a constant column gets std 1)."""

    def __init__(self, x):
        x = np.asarray(x, dtype=np.float64)
        self.mean = x.mean(axis=0)
        std = x.std(axis=0)
        self.std = np.where(std > 1e-12, std, 1.0)

    def __call__(self, x):
        return (np.asarray(x, dtype=np.float64) - self.mean) / self.std


def _linear_from(weight, bias):
    """nn.Linear holding float64 numpy weight [out, in] and bias [out] as float32."""
    lin = nn.Linear(weight.shape[1], weight.shape[0])
    with torch.no_grad():
        lin.weight.copy_(torch.from_numpy(np.asarray(weight, dtype=np.float32)))
        lin.bias.copy_(torch.from_numpy(np.asarray(bias, dtype=np.float32)))
    return lin


# -- DNN -------------------------------------------------------------------------

class ArrayDNN(nn.Module):
    """Fig. 4.13, training form. forward: raw ratios [B, C] -> markers [B, 3M] metres."""

    def __init__(self, cells, outputs, input_width=None, hidden=THESIS_HIDDEN):
        super().__init__()
        self.cells, self.outputs = int(cells), int(outputs)
        self.input_width = int(input_width or cells)
        self.hidden = tuple(int(h) for h in hidden)
        if min((self.input_width,) + self.hidden) < 1:
            raise ValueError(f"layer widths must be positive, got input {self.input_width}, hidden {self.hidden}")
        layers, c_in = [], self.cells
        for w in (self.input_width,) + self.hidden:
            layers += [nn.Linear(c_in, w), nn.ReLU(), nn.BatchNorm1d(w)]
            c_in = w
        self.trunk = nn.Sequential(*layers)
        self.out = nn.Linear(c_in, self.outputs)
        for name, size in (("in_mean", cells), ("in_std", cells), ("out_mean", outputs), ("out_std", outputs)):
            self.register_buffer(name, torch.zeros(size) if "mean" in name else torch.ones(size))

    def set_standardisation(self, x_std, y_std):
        with torch.no_grad():
            self.in_mean.copy_(torch.from_numpy(x_std.mean.astype(np.float32)))
            self.in_std.copy_(torch.from_numpy(x_std.std.astype(np.float32)))
            self.out_mean.copy_(torch.from_numpy(y_std.mean.astype(np.float32)))
            self.out_std.copy_(torch.from_numpy(y_std.std.astype(np.float32)))

    def normalised_forward(self, x_n):
        """Standardised inputs -> standardised outputs (what the loss sees)."""
        return self.out(self.trunk(x_n))

    def forward(self, ratios):
        y_n = self.normalised_forward((ratios - self.in_mean) / self.in_std)
        return y_n * self.out_std + self.out_mean

    def config(self):
        return {"kind": "dnn", "cells": self.cells, "outputs": self.outputs, "input_width": self.input_width,
                "hidden": list(self.hidden)}


class MLPInference(nn.Module):
    """Gemm/Relu chain: the DNN with standardisation and eval-mode BatchNorm folded in."""

    def __init__(self, linears):
        super().__init__()
        self.hidden = nn.ModuleList(linears[:-1])
        self.out = linears[-1]

    def forward(self, cells):
        h = cells
        for lin in self.hidden:
            h = torch.relu(lin(h))
        return self.out(h)


def fold_dnn(model):
    """An exactly equivalent (to float rounding) Gemm/Relu network for export."""
    model = model.eval()
    with torch.no_grad():
        linears = [m for m in model.trunk if isinstance(m, nn.Linear)] + [model.out]
        norms = [m for m in model.trunk if isinstance(m, nn.BatchNorm1d)]
        folded = []
        pending = None  # the (scale, shift) of the BatchNorm feeding the next Linear
        for k, lin in enumerate(linears):
            w = lin.weight.detach().double().clone()
            b = lin.bias.detach().double().clone()
            if k == 0:  # x_n = (r - mean) / std
                w = w / model.in_std.double().view(1, -1)
                b = b - w @ model.in_mean.double()
            if pending is not None:
                scale, shift = pending
                b = b + w @ shift
                w = w * scale.view(1, -1)
            if k == len(linears) - 1:  # y = y_n * std + mean
                w = w * model.out_std.double().view(-1, 1)
                b = b * model.out_std.double() + model.out_mean.double()
            folded.append(_linear_from(w.numpy(), b.numpy()))
            if k < len(norms):
                bn = norms[k]
                scale = bn.weight.detach().double() / torch.sqrt(bn.running_var.double() + bn.eps)
                pending = (scale, bn.bias.detach().double() - bn.running_mean.double() * scale)
    return MLPInference(folded).eval()


# -- linear regression ---------------------------------------------------------------

class LinearRegressor(nn.Module):
    """y = W r + b on raw ratios (standardisation folded into W, b)."""

    def __init__(self, cells, outputs):
        super().__init__()
        self.cells, self.outputs = int(cells), int(outputs)
        self.linear = nn.Linear(self.cells, self.outputs)

    def forward(self, cells):
        return self.linear(cells)

    def config(self):
        return {"kind": "lr", "cells": self.cells, "outputs": self.outputs}


def fit_linear(x, y, ridge=1e-6):
    """Ridge least squares on standardised inputs; `ridge` is relative to the frame count."""
    xs = Standardiser(x)
    xn = xs(x)
    y = np.asarray(y, dtype=np.float64)
    y_mean = y.mean(axis=0)
    a = xn.T @ xn + ridge * len(xn) * np.eye(xn.shape[1])
    w_n = np.linalg.solve(a, xn.T @ (y - y_mean))  # [C, out]
    w = (w_n / xs.std[:, None]).T  # [out, C] on raw ratios
    b = y_mean - w @ xs.mean
    model = LinearRegressor(x.shape[1], y.shape[1])
    model.linear = _linear_from(w, b)
    return model.eval()


# -- RBF kernel ridge ("SVM") -------------------------------------------------------

class KernelRidge(nn.Module):
    """f(r) = sum_j a_j exp(-gamma ||x - z_j||^2) + b, x = standardised r, written as
    Gemm (standardise) -> Gemm(x; 2 gamma Z^T, -gamma |z|^2) + MatMul(x*x; -gamma 1) -> Exp -> Gemm,
    so that an ONNX reader needs no ReduceSum, Sub, Pow or broadcasting of unequal shapes."""

    def __init__(self, cells, outputs, centres):
        super().__init__()
        self.cells, self.outputs, self.centres = int(cells), int(outputs), int(centres)
        self.standardise = nn.Linear(self.cells, self.cells)
        self.cross = nn.Linear(self.cells, self.centres)
        self.square = nn.Linear(self.cells, self.centres, bias=False)
        self.combine = nn.Linear(self.centres, self.outputs)

    def forward(self, cells):
        x = self.standardise(cells)
        return self.combine(torch.exp(self.cross(x) + self.square(x * x)))

    def config(self):
        return {"kind": "svm", "cells": self.cells, "outputs": self.outputs, "centres": self.centres}


def _rbf(x, z, gamma):
    d2 = (x * x).sum(1)[:, None] - 2.0 * x @ z.T + (z * z).sum(1)[None, :]
    return np.exp(-gamma * np.maximum(d2, 0.0))


def _median_sq_distance(x, rng, pairs=4000):
    i = rng.integers(0, len(x), pairs)
    j = rng.integers(0, len(x), pairs)
    d2 = ((x[i] - x[j]) ** 2).sum(1)
    d2 = d2[d2 > 0]
    return float(np.median(d2)) if len(d2) else 1.0


def fit_kernel_ridge(x, y, x_val, y_val, marker_count, max_centres=1000, gamma_factors=(0.25, 0.5, 1.0, 2.0, 4.0),
                     lambdas=(1e-6, 1e-5, 1e-4, 1e-3, 1e-2), seed=1, log=None):
    """Returns (model, info). Hyper-parameters by validation mean marker error (training error if no
    validation frames). lambda is relative: the penalty is lambda * N * a^T K_zz a."""
    rng = np.random.default_rng(seed)
    xs = Standardiser(x)
    xn, y = xs(x), np.asarray(y, dtype=np.float64)
    y_mean = y.mean(axis=0)
    yc = y - y_mean
    centre_idx = np.sort(rng.choice(len(xn), size=min(max_centres, len(xn)), replace=False))
    z = xn[centre_idx]
    has_val = x_val is not None and len(x_val) > 0
    xv, yv = (xs(x_val), np.asarray(y_val, np.float64)) if has_val else (xn, y)
    med = _median_sq_distance(xn, rng)
    best = None
    for factor in gamma_factors:
        gamma = factor / med
        k_nz = _rbf(xn, z, gamma)
        k_zz = _rbf(z, z, gamma)
        k_vz = _rbf(xv, z, gamma)
        gram, rhs = k_nz.T @ k_nz, k_nz.T @ yc
        for lam in lambdas:
            a = gram + lam * len(xn) * k_zz + 1e-10 * np.trace(gram) / len(z) * np.eye(len(z))
            try:
                alpha = np.linalg.solve(a, rhs)
            except np.linalg.LinAlgError:
                continue
            err = float(np.mean(_marker_err(k_vz @ alpha + y_mean, yv, marker_count))) * 1000.0
            if log:
                log(f"svm: gamma {factor:g}/median ({gamma:.4g}), lambda {lam:g}: "
                    f"{'validation' if has_val else 'training'} {err:.3f} mm")
            if best is None or err < best[0]:
                best = (err, factor, gamma, lam, alpha)
    if best is None:
        raise RuntimeError("kernel ridge: every (gamma, lambda) gave a singular system")
    err, factor, gamma, lam, alpha = best
    model = KernelRidge(x.shape[1], y.shape[1], len(z))
    model.standardise = _linear_from(np.diag(1.0 / xs.std), -xs.mean / xs.std)
    model.cross = _linear_from((2.0 * gamma * z), -gamma * (z * z).sum(1))
    model.square = nn.Linear(model.cells, model.centres, bias=False)
    with torch.no_grad():
        model.square.weight.fill_(-gamma)
    model.combine = _linear_from(alpha.T, y_mean)
    info = {"kernel": "rbf", "method": "kernel ridge (subset of regressors)", "centres": int(len(z)),
            "gamma": gamma, "gamma_factor_of_median": factor, "median_sq_distance": med, "lambda": lam,
            ("val_error_mm" if has_val else "train_error_mm"): err}
    return model.eval(), info


def _marker_err(pred, target, m):
    p = np.asarray(pred).reshape(-1, m, 3)
    t = np.asarray(target).reshape(-1, m, 3)
    return np.sqrt(((p - t) ** 2).sum(2))


# -- training --------------------------------------------------------------------

class DnnConfig:
    def __init__(self, epochs=200, batch=256, lr=1e-4, weight_lambda=1e-5, patience=10, hidden=THESIS_HIDDEN,
                 input_width=None, seed=1, threads=2):
        self.epochs, self.batch, self.lr = int(epochs), int(batch), float(lr)
        self.weight_lambda, self.patience = float(weight_lambda), int(patience)
        self.hidden, self.input_width = tuple(hidden), input_width
        self.seed, self.threads = int(seed), int(threads)
        if self.epochs < 1 or self.batch < 2 or self.lr <= 0 or self.patience < 1 or self.weight_lambda < 0:
            raise ValueError("epochs >= 1, batch >= 2, lr > 0, patience >= 1 and lambda >= 0 are required")

    @staticmethod
    def tiny(**overrides):
        """CI size: seconds, not minutes (width 64, larger steps)."""
        args = dict(epochs=40, batch=64, lr=1e-3, hidden=TINY_HIDDEN, patience=10)
        args.update({k: v for k, v in overrides.items() if v is not None})
        return DnnConfig(**args)

    def as_dict(self):
        return {"epochs": self.epochs, "batch": self.batch, "lr": self.lr, "lambda": self.weight_lambda,
                "patience": self.patience, "hidden": list(self.hidden), "input_width": self.input_width,
                "seed": self.seed, "threads": self.threads, "optimizer": "adam (torch defaults)"}


def predict(model, x, batch=4096):
    model.eval()
    out = []
    with torch.no_grad():
        for i in range(0, len(x), batch):
            out.append(model(torch.from_numpy(np.ascontiguousarray(x[i:i + batch], dtype=np.float32))).numpy())
    return np.concatenate(out) if out else np.zeros((0, model.outputs), np.float32)


def fit_dnn(x, y, x_val, y_val, marker_count, cfg, log=None):
    """Minibatch Adam on eq. 4.9 with early stopping on the validation mean marker error (mm).
    Returns (model with its best-validation weights, info)."""
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    x = np.asarray(x, np.float32)
    y = np.asarray(y, np.float32)
    n = len(x)
    if n < 2:
        raise ValueError(f"{n} training frames: the DNN needs at least 2 (BatchNorm)")
    xs, ys = Standardiser(x), Standardiser(y)
    model = ArrayDNN(x.shape[1], y.shape[1], cfg.input_width, cfg.hidden)
    model.set_standardisation(xs, ys)
    xt = torch.from_numpy(xs(x).astype(np.float32))
    yt = torch.from_numpy(ys(y).astype(np.float32))
    # Adam's weight_decay w adds w * theta to the gradient: the gradient of (w / 2) ||theta||^2.
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr, weight_decay=2.0 * cfg.weight_lambda)
    generator = torch.Generator().manual_seed(cfg.seed)
    has_val = x_val is not None and len(x_val) > 0
    batch = min(cfg.batch, n)
    best = {"err": math.inf, "epoch": 0, "state": copy.deepcopy(model.state_dict())}
    history, stale, start = [], 0, time.time()
    for epoch in range(1, cfg.epochs + 1):
        t0 = time.time()
        model.train()
        order = torch.randperm(n, generator=generator)
        total, count = 0.0, 0
        for i in range(0, n, batch):
            idx = order[i:i + batch]
            if len(idx) < 2:  # BatchNorm needs two samples in training mode
                continue
            optimizer.zero_grad(set_to_none=True)
            diff = model.normalised_forward(xt[idx]) - yt[idx]
            loss = (diff * diff).sum(1).mean()  # eq. 4.9's data term, per frame
            loss.backward()
            optimizer.step()
            total += float(loss) * len(idx)
            count += len(idx)
        entry = {"epoch": epoch, "train_loss": total / max(count, 1), "seconds": time.time() - t0}
        if has_val:
            err = float(np.mean(_marker_err(predict(model, x_val), y_val, marker_count))) * 1000.0
            entry["val_error_mm"] = err
            if err < best["err"] - 1e-4:
                best = {"err": err, "epoch": epoch, "state": copy.deepcopy(model.state_dict())}
                stale = 0
            else:
                stale += 1
        history.append(entry)
        if log:
            msg = f"dnn epoch {epoch}/{cfg.epochs}: train loss {entry['train_loss']:.4f}"
            if has_val:
                msg += f", validation {entry['val_error_mm']:.2f} mm (best {best['err']:.2f} @ {best['epoch']})"
            log(msg + f", {entry['seconds']:.2f} s")
        if has_val and stale >= cfg.patience:
            if log:
                log(f"dnn: early stop, no validation improvement for {cfg.patience} epochs")
            break
    if has_val:
        model.load_state_dict(best["state"])
    model.eval()
    seconds = time.time() - start
    info = {"epochs_run": len(history), "best_epoch": best["epoch"] if has_val else len(history),
            "val_error_mm": best["err"] if has_val else None, "seconds": seconds,
            "seconds_per_epoch": seconds / max(len(history), 1), "parameters": parameter_count(model),
            "history": history}
    return model, info


def fit(kind, x, y, x_val, y_val, marker_count, dnn_config=None, lr_ridge=1e-6, max_centres=1000, seed=1,
        log=None):
    """Trains one regressor. Returns (torch model taking raw ratios, info dict with val_error_mm)."""
    start = time.time()
    if kind == "dnn":
        return fit_dnn(x, y, x_val, y_val, marker_count, dnn_config or DnnConfig(seed=seed), log)
    if kind == "lr":
        model = fit_linear(x, y, lr_ridge)
        info = {"ridge": lr_ridge, "epochs_run": 0}
    elif kind == "svm":
        model, info = fit_kernel_ridge(x, y, x_val, y_val, marker_count, max_centres=max_centres, seed=seed,
                                       log=log)
        info["epochs_run"] = 0
    else:
        raise ValueError(f"unknown model kind '{kind}': expected one of {', '.join(KINDS)}")
    if x_val is not None and len(x_val):
        info["val_error_mm"] = float(np.mean(_marker_err(predict(model, x_val), y_val, marker_count))) * 1000.0
    else:
        info["val_error_mm"] = None
    info["seconds"] = time.time() - start
    info["parameters"] = parameter_count(model)
    return model, info


def parameter_count(model):
    return int(sum(p.numel() for p in model.parameters()))


# -- rebuild / export ----------------------------------------------------------------

def build_from_config(config):
    kind = config.get("kind")
    if kind == "dnn":
        return ArrayDNN(config["cells"], config["outputs"], config.get("input_width"), config["hidden"])
    if kind == "lr":
        return LinearRegressor(config["cells"], config["outputs"])
    if kind == "svm":
        return KernelRidge(config["cells"], config["outputs"], config["centres"])
    raise ValueError(f"unknown model kind {kind!r}: expected one of {', '.join(KINDS)}")


def inference_form(model):
    if isinstance(model, ArrayDNN):
        return fold_dnn(model)
    return model.eval()


def probe_inputs(cells, count=32, seed=0):
    """Ratios around 1, as the read-out gives (C/C0 from ~0.6 to ~2.5)."""
    return torch.from_numpy(np.random.default_rng(seed).uniform(0.7, 1.8, size=(count, cells)).astype(np.float32))


def export_onnx(model, path, opset=11):
    """Writes the inference form, batch 1 fixed ("cells" [1, C] -> "markers" [1, 3M]), after checking that
    it computes what `model` computes. Returns the largest difference seen, metres."""
    model.eval()
    inference = inference_form(model)
    probe = probe_inputs(model.cells)
    with torch.no_grad():
        ref = model(probe)
        gap = float((inference(probe) - ref).abs().max())
    scale = max(1.0, float(ref.abs().max()))
    if gap > 1e-4 * scale:
        raise RuntimeError(f"inference form differs from the trained model by {gap:g} m (a bug in the folding)")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    # Batch 1, fixed shapes: the C++ runs one frame per call and OpenCV 4.6 DNN wants known shapes.
    torch.onnx.export(inference, torch.ones(1, model.cells), path, opset_version=opset, input_names=["cells"],
                      output_names=["markers"], do_constant_folding=True)
    return gap
