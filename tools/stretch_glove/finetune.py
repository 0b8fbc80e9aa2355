#!/usr/bin/python3
"""Fine-tunes a generic model on a short personal recording (Glauser 2019,
scenario 5: about 5 minutes of one person's data with ground truth) and writes
NAME.onnx + NAME.json + NAME.pt.

  /usr/bin/python3 tools/stretch_glove/finetune.py --model generic.pt --data PERSONAL_DATA \\
      --session 0 --minutes 5 --out build/glove/tuned.onnx

All weights are trained (as in the thesis), from the generic model's weights,
with a fresh optimizer. The inputs are normalised the way the generic model
was trained (its sidecar says: the session's own min-max, or the training
data's global min-max). The last --val-fraction of the personal data is held
out for early stopping; the best epoch's weights are kept, and an epoch 0 (the
generic model itself) competes too, so fine-tuning never makes the held-out
error worse.
"""

import argparse
import copy
import os
import sys
import time

# Before numpy/torch load an OpenMP runtime: see training.py.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np

import dataset as ds
import train
import training

# Thesis: lr 1e-6, batch 64 (sec. 5.4.2). On simulated subjects 1e-5 reached
# the same error as 1e-6 about ten times sooner, while 1e-4 and above did
# worse; README.md "Fine-tuning learning rate" has the numbers.
DEFAULT_LR = 1e-5
DEFAULT_BATCH = 64


def personal_frames(data, sessions, minutes):
    """The first `minutes` of the chosen sessions (in session order), as one recording."""
    return personal_frames_of(data, data.frames(sessions), minutes)


def personal_frames_of(data, frames, minutes):
    limit = int(round(minutes * 60.0 * data.frame_rate_hz)) if minutes > 0 else len(frames)
    return frames[:limit]


def finetune(model, data, frames, cfg, calibration, global_min=None, global_max=None, val_fraction=0.2,
             log=print, label=""):
    """Fine-tunes `model` in place on `frames`; returns the fit summary (epoch 0 = the model as given)."""
    train_f, val_f = ds.validation_split(data, frames, val_fraction)
    x_train = data.inputs(train_f, calibration, global_min, global_max)
    y_train, mask = data.targets(train_f)
    x_val = data.inputs(val_f, calibration, global_min, global_max)
    y_val, _ = data.targets(val_f)
    before = training.angle_errors_deg(training.predict(model, x_val), y_val, data.output_grid)["mean_deg"] \
        if len(val_f) else None
    start_state = copy.deepcopy(model.state_dict())
    result = training.fit(model, x_train, y_train, x_val, y_val, mask, cfg, data.output_grid, log=log, label=label)
    if before is not None and result["best_val_deg"] is not None and result["best_val_deg"] > before:
        model.load_state_dict(start_state)  # no epoch beat the generic model on held-out personal data
        result["best_epoch"] = 0
        result["best_val_deg"] = before
    result["val_deg_before"] = before
    return result


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", required=True, help="the generic model's NAME.pt (written by train.py)")
    p.add_argument("--data", required=True, help="dataset directory holding the personal recording")
    p.add_argument("--session", action="append", default=[],
                   help="personal session index (into meta.json sessions); repeatable or comma-separated")
    p.add_argument("--subject", type=int, help="instead of --session: this subject's first session")
    p.add_argument("--minutes", type=float, default=5.0, help="use the first M minutes (default 5; 0 = all)")
    p.add_argument("--val-fraction", type=float, default=0.2, help="held-out tail for early stopping (default 0.2)")
    p.add_argument("--out", required=True, help="output NAME.onnx (NAME.json and NAME.pt next to it)")
    train.add_training_arguments(p, epochs=30, batch=DEFAULT_BATCH, lr=DEFAULT_LR, patience=5)
    a = p.parse_args(argv)
    log = (lambda *_: None) if a.quiet else print
    try:
        paths = training.stem_paths(a.out)
        cfg = training.TrainConfig(epochs=a.epochs, batch=a.batch, lr=a.lr, optimizer=a.optimizer,
                                   patience=a.patience, seed=a.seed, threads=a.threads)
        if not 0.0 < a.val_fraction < 0.9:
            raise ValueError(f"--val-fraction {a.val_fraction}: expected 0 < f < 0.9")
        data = ds.Dataset(a.data)
        model, generic_sidecar = training.load_checkpoint(a.model)
        training.check_compatible(generic_sidecar, data, a.model)
        sessions = [v for text in a.session for v in training.parse_int_list(text, "--session")]
        if a.subject is not None:
            if sessions:
                raise ValueError("give --session or --subject, not both")
            of_subject = data.sessions_of(a.subject)
            if not of_subject:
                raise ValueError(f"--subject {a.subject}: no such subject in {a.data} (subjects: {data.subjects()})")
            sessions = of_subject[:1]
        if not sessions:
            raise ValueError("choose the personal recording with --session or --subject")
        for s in sessions:
            if not 0 <= s < len(data.sessions):
                raise ValueError(f"--session {s}: the dataset has sessions 0..{len(data.sessions) - 1}")
    except (ValueError, FileNotFoundError, ds.DatasetError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    training.configure_torch(cfg.threads, cfg.seed)
    norm = generic_sidecar.get("normalisation", {})
    calibration = norm.get("calibration", "session")
    gmin = np.asarray(norm["global_min_pf"], np.float32) if calibration == "global" else None
    gmax = np.asarray(norm["global_max_pf"], np.float32) if calibration == "global" else None
    frames = personal_frames(data, sessions, a.minutes)
    log(f"fine-tuning {a.model} ({generic_sidecar.get('model', {}).get('kind', '?')}) on {len(frames)} frames "
        f"({len(frames) / data.frame_rate_hz / 60:.1f} min) of sessions {sessions}; lr {cfg.lr:g}, batch {cfg.batch}")
    started = time.time()
    result = finetune(model, data, frames, cfg, calibration, gmin, gmax, a.val_fraction, log=log)
    _, val_f = ds.validation_split(data, frames, a.val_fraction)
    y_val, _ = data.targets(val_f)
    validation = training.angle_errors_deg(
        training.predict(model, data.inputs(val_f, calibration, gmin, gmax)), y_val, data.output_grid)
    sidecar = training.build_sidecar(
        data, model, calibration=calibration, global_min=gmin, global_max=gmax, seed=cfg.seed,
        training=dict(cfg.as_dict(), **{k: v for k, v in result.items() if k != "history"},
                      val_fraction=a.val_fraction, minutes=a.minutes),
        validation=validation, data_summary=ds.summary(data, frames),
        extra={"finetuned_from": {"path": os.path.abspath(a.model), "seed": generic_sidecar.get("seed"),
                                  "training": {k: generic_sidecar.get("training", {}).get(k)
                                               for k in ("epochs_run", "best_epoch", "lr", "batch")},
                                  "validation": generic_sidecar.get("validation")}})
    training.save_model(model, paths["onnx"], sidecar)
    before = result["val_deg_before"]
    print(f"wrote {paths['onnx']}: {result['epochs_run']} epochs in {time.time() - started:.1f} s, best epoch "
          f"{result['best_epoch']}; held-out personal error {before:.2f} -> {validation['mean_deg']:.2f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
