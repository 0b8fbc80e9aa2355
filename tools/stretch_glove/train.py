#!/usr/bin/python3
"""Trains a stretch-glove pose network (U-Net of Glauser 2019 Table C.1, or the
FCN baseline) on a dataset directory and writes NAME.onnx + NAME.json + NAME.pt.

  /usr/bin/python3 tools/stretch_glove/train.py --data DATA --model unet --seed 1 --out build/glove/generic.onnx

Deterministic: the same data, arguments, seed, --threads and torch build give
the same weights. The last tenth of every training session (contiguous, so no
near-duplicate neighbouring frames leak) is held out for early stopping.
"""

import argparse
import os
import sys
import time

# Before numpy/torch load an OpenMP runtime: see training.py.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np

import dataset as ds
import models
import training


def select_sessions(data, subjects=None, exclude_subjects=None, sessions=None):
    """Session indices of the chosen subjects (all if None), minus excluded subjects, within `sessions` if given."""
    chosen = []
    for s in range(len(data.sessions)):
        subject_ids = set(int(v) for v in np.unique(data.subject[data.session == s]))
        if subjects is not None and not subject_ids & set(subjects):
            continue
        if exclude_subjects is not None and subject_ids & set(exclude_subjects):
            continue
        if sessions is not None and s not in sessions:
            continue
        chosen.append(s)
    return chosen


def add_training_arguments(p, epochs=60, batch=256, lr=2e-4, patience=8):
    p.add_argument("--epochs", type=int, default=epochs, help=f"maximum epochs (default {epochs})")
    p.add_argument("--batch", type=int, default=batch, help=f"minibatch size (default {batch})")
    p.add_argument("--lr", type=float, default=lr, help=f"learning rate (default {lr:g})")
    p.add_argument("--optimizer", choices=["adam", "sgd"], default="adam",
                   help="adam (beta1 0.5, beta2 0.999 as Appendix C.1) or plain sgd")
    p.add_argument("--patience", type=int, default=patience,
                   help=f"stop after this many epochs without validation improvement (default {patience})")
    p.add_argument("--seed", type=int, default=1, help="seeds initialisation and shuffling (default 1)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads (default 2)")
    p.add_argument("--quiet", action="store_true", help="no per-epoch progress")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="dataset directory (proprio sim-glove --out DIR)")
    p.add_argument("--model", choices=models.MODEL_KINDS, default="unet")
    p.add_argument("--out", required=True, help="output NAME.onnx (NAME.json and NAME.pt are written next to it)")
    p.add_argument("--subjects", help="train on these subject ids only, e.g. 0,1,2 (default: all)")
    p.add_argument("--exclude-subject", action="append", default=[],
                   help="leave these subject ids out (repeatable or comma-separated): leave-one-subject-out")
    p.add_argument("--sessions", help="train on these session indices (into meta.json sessions) only")
    p.add_argument("--calibration", choices=ds.CALIBRATION_MODES, default="session",
                   help="session: each session's own min-max (scenario 4); global: min-max over all training "
                        "data, stored in the sidecar (scenario 3)")
    p.add_argument("--val-fraction", type=float, default=0.1,
                   help="tail of each session held out for early stopping (default 0.1; 0 = none)")
    p.add_argument("--max-train-frames", type=int, default=0,
                   help="use every k-th training frame so at most this many remain (default 0 = all)")
    p.add_argument("--unet-width", type=int, default=16, help="U-Net channel width; 64 = Table C.1 (default 16)")
    p.add_argument("--fcn-hidden", default="384,384,384,192", help="FCN hidden widths (default 384,384,384,192)")
    p.add_argument("--opset", type=int, default=training.DEFAULT_OPSET, help="ONNX opset (OpenCV 4.6 reads 11-13)")
    add_training_arguments(p)
    a = p.parse_args(argv)
    log = (lambda *_: None) if a.quiet else print
    try:
        paths = training.stem_paths(a.out)
        cfg = training.TrainConfig(epochs=a.epochs, batch=a.batch, lr=a.lr, optimizer=a.optimizer,
                                   patience=a.patience, seed=a.seed, threads=a.threads)
        subjects = training.parse_int_list(a.subjects, "--subjects")
        exclude = [v for text in a.exclude_subject for v in training.parse_int_list(text, "--exclude-subject")]
        sessions = training.parse_int_list(a.sessions, "--sessions")
        hidden = training.parse_int_list(a.fcn_hidden, "--fcn-hidden")
        if not 0.0 <= a.val_fraction < 0.9:
            raise ValueError(f"--val-fraction {a.val_fraction}: expected 0 <= f < 0.9")
        if a.opset not in (11, 12, 13):
            raise ValueError(f"--opset {a.opset}: OpenCV 4.6 DNN reads opsets 11-13")
        data = ds.Dataset(a.data)
    except (ValueError, ds.DatasetError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    training.configure_torch(cfg.threads, cfg.seed)
    chosen = select_sessions(data, subjects, exclude or None, sessions)
    if not chosen:
        print("error: the subject/session selection leaves no training sessions", file=sys.stderr)
        return 2
    frames = data.frames(chosen)
    train_f, val_f = ds.validation_split(data, frames, a.val_fraction)
    train_f = ds.strided(train_f, a.max_train_frames)
    val_f = ds.strided(val_f, a.max_train_frames // 5)
    gmin = gmax = None
    if a.calibration == "global":
        gmin, gmax = data.global_calibration(train_f)
    x_train = data.inputs(train_f, a.calibration, gmin, gmax)
    y_train, mask = data.targets(train_f)
    x_val = data.inputs(val_f, a.calibration, gmin, gmax)
    y_val, _ = data.targets(val_f)

    model = models.build_model(a.model, unet_width=a.unet_width, fcn_hidden=hidden)
    models.xavier_init(model)
    models.set_output_range(model, *training.output_range_from_targets(y_train, mask))
    log(f"{a.model}: {models.parameter_count(model)} parameters; {len(train_f)} training and {len(val_f)} "
        f"validation frames from {len(chosen)} sessions; calibration {a.calibration}; {cfg.threads} threads; seed {cfg.seed}")
    started = time.time()
    result = training.fit(model, x_train, y_train, x_val, y_val, mask, cfg, data.output_grid, log=log)
    validation = training.angle_errors_deg(training.predict(model, x_val), y_val, data.output_grid) if len(val_f) else None
    summary = ds.summary(data, frames)
    sidecar = training.build_sidecar(
        data, model, calibration=a.calibration, global_min=gmin, global_max=gmax, seed=cfg.seed,
        training=dict(cfg.as_dict(), **{k: v for k, v in result.items() if k != "history"},
                      val_fraction=a.val_fraction, max_train_frames=a.max_train_frames),
        validation=validation, data_summary=summary, opset=a.opset)
    training.save_model(model, paths["onnx"], sidecar, a.opset)
    print(f"wrote {paths['onnx']} (+ {os.path.basename(paths['json'])}, {os.path.basename(paths['pt'])}): "
          f"{result['epochs_run']} epochs in {time.time() - started:.1f} s "
          f"({result['seconds_per_epoch']:.2f} s/epoch), best epoch {result['best_epoch']}"
          + (f", validation mean error {validation['mean_deg']:.2f} deg" if validation else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
