#!/usr/bin/python3
"""Evaluates the stretch-glove pose network in the structure of Glauser 2019
Table 5.1 on a (simulated) dataset: subjects as rows, the five scenarios as
columns, mean joint-angle errors in degrees, per DoF too; and the sensor
ablation of Fig. 5.10 (14 -> 44 cells by the thesis's sensor categories).

  /usr/bin/python3 tools/stretch_glove/evaluate.py --data DATA --model unet \\
      --out-json build/glove/eval.json --out-md build/glove/eval.md

Per subject, the test frames are the last --test-fraction of the task phase of
its last session (the same frames in every column):
  (1) intra:  personalised, trained on the same donning: the subject's other
              sessions worn without taking the glove off (if any) plus the
              test session's own earlier frames (its exploration and task
              frames before the test part);
  (2) inter:  personalised, trained on the subject's sessions of other
              donnings only (the glove was taken off in between);
  (3) generic w/o calibration: trained on all other subjects (leave one
              subject out), inputs normalised with the per-cell min-max of the
              training data, in training and testing;
  (4) generic with calibration: as (3), each session normalised with its own
              exploration-phase min-max (the C++ calibrator's);
  (5) fine-tuned: model (4) fine-tuned on the first --finetune-minutes of the
              subject's first session of another donning;
  (5b) (column 6) fine-tuned on the test session's own earlier frames (the
              training data of (1)): the personal recording made without taking
              the glove off before use.
A column is "n/a" where the subject lacks the sessions it needs. Simulated
accuracy is not real-world accuracy: these numbers compare methods on the
simulator, they do not predict a real glove's error.
"""

import argparse
import json
import math
import os
import sys
import time

# Before numpy/torch load an OpenMP runtime: see training.py.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np

import dataset as ds
import finetune as ft
import models
import train
import training

SCENARIOS = {
    1: "(1) Intra",
    2: "(2) Inter",
    3: "(3) w/o Calib",
    4: "(4) w Calib",
    5: "(5) Tuned",
    6: "(5b) Tuned, same donning",
}
ABLATION_STAGES = [
    ("joint", ["joint"]),
    ("+ abduction", ["joint", "abduction"]),
    ("+ perpendicular", ["joint", "abduction", "perpendicular"]),
    ("+ dorsum (all)", ["joint", "abduction", "perpendicular", "dorsum"]),
]


def subject_plan(data, subject, test_fraction, finetune_minutes):
    sessions = data.sessions_of(subject)
    test_session = sessions[-1]
    task = data.frames([test_session], phase=1)
    n_test = max(1, int(round(test_fraction * len(task))))
    test = task[len(task) - n_test:]
    whole = data.frames([test_session])
    head = whole[whole < test[0]]
    test_donning = data.donning(test_session)
    same = [s for s in sessions[:-1] if data.donning(s) == test_donning]
    other = [s for s in sessions if data.donning(s) != test_donning]
    personal = ft.personal_frames(data, other[:1], finetune_minutes) if other else np.zeros(0, np.int64)
    return {
        "sessions": sessions,
        "test_session": test_session,
        "test": test,
        "intra_train": np.concatenate([data.frames(same), head]) if same else head,
        "inter_train": data.frames(other) if other else np.zeros(0, np.int64),
        "personal": personal,
        "personal_sessions": other[:1],
    }


class Evaluator:
    def __init__(self, data, args, log):
        self.data = data
        self.a = args
        self.log = log
        self.mask = ds.output_mask(data.output_grid)
        self.cfg = training.TrainConfig(epochs=args.epochs, batch=args.batch, lr=args.lr, optimizer=args.optimizer,
                                        patience=args.patience, seed=args.seed, threads=args.threads)

    def train_model(self, frames, calibration, gmin=None, gmax=None, cell_mask=None, label=""):
        train_f, val_f = ds.validation_split(self.data, frames, self.a.val_fraction)
        train_f = ds.strided(train_f, self.a.max_train_frames)
        val_f = ds.strided(val_f, max(self.a.max_train_frames // 5, 0))
        x_train = self.data.inputs(train_f, calibration, gmin, gmax, cell_mask)
        y_train, mask = self.data.targets(train_f)
        x_val = self.data.inputs(val_f, calibration, gmin, gmax, cell_mask)
        y_val, _ = self.data.targets(val_f)
        # Every model starts from the same seed, so columns differ by data, not by luck of the draw.
        training.configure_torch(self.cfg.threads, self.cfg.seed)
        model = models.build_model(self.a.model, unet_width=self.a.unet_width,
                                   fcn_hidden=training.parse_int_list(self.a.fcn_hidden, "--fcn-hidden"))
        models.xavier_init(model)
        models.set_output_range(model, *training.output_range_from_targets(y_train, mask))
        result = training.fit(model, x_train, y_train, x_val, y_val, mask, self.cfg, self.data.output_grid,
                              log=self.log if self.a.verbose else None, label=label)
        self.log(f"  [{label}] {result['epochs_run']} epochs, {len(train_f)} frames, "
                 f"{result['seconds_per_epoch']:.1f} s/epoch, validation {result['best_val_deg']:.2f} deg")
        return model, result

    def test(self, model, frames, calibration, gmin=None, gmax=None, cell_mask=None):
        x = self.data.inputs(frames, calibration, gmin, gmax, cell_mask)
        y, _ = self.data.targets(frames)
        return training.angle_errors_deg(training.predict(model, x), y, self.data.output_grid)

    @staticmethod
    def _entry(errors, result, extra=None):
        entry = dict(errors)
        entry["train_frames"] = result["train_frames"]
        entry["epochs"] = result["epochs_run"]
        entry["seconds"] = round(result["seconds"], 2)
        if extra:
            entry.update(extra)
        return entry


def parse_lrs(text):
    try:
        lrs = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--finetune-lr '{text}': expected comma-separated numbers, e.g. 1e-6,1e-4") from None
    if not lrs or min(lrs) <= 0:
        raise ValueError(f"--finetune-lr '{text}': learning rates must be positive")
    return lrs


def cell_categories(data, layout_path):
    cats = data.meta.get("cell_categories")
    if cats is None and layout_path:
        import tomllib
        with open(layout_path, "rb") as f:
            layout = tomllib.load(f)
        cats = [c.get("category") for c in layout.get("cell", [])]
    if cats is not None and len(cats) != data.cell_count:
        raise ValueError(f"{len(cats)} cell categories for {data.cell_count} cells")
    return cats


def fmt(v):
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.1f}"


def markdown(report):
    lines = []
    cfg = report["config"]
    lines.append(f"# Stretch-glove pose network on simulated subjects ({cfg['model']})")
    lines.append("")
    lines.append("Simulated accuracy is not real-world accuracy: these numbers compare methods on the simulator.")
    lines.append("")
    lines.append(f"Data: `{cfg['data']}` ({cfg['layout']}); test = last {cfg['test_fraction']:.0%} of the task phase "
                 f"of each subject's last session. Model {cfg['model']} ({cfg['parameters']} parameters), "
                 f"{cfg['epochs']} epochs max, batch {cfg['batch']}, lr {cfg['lr']:g}, seed {cfg['seed']}, "
                 f"at most {cfg['max_train_frames']} training frames per model. Fine-tuning: "
                 f"{cfg['finetune_minutes']} min, lr {cfg['finetune_lrs'][0]:g}, batch {cfg['finetune_batch']}.")
    lines.append("")
    cols = report["scenarios"]
    lines.append("Mean joint-angle error (degrees), structure of Table 5.1:")
    lines.append("")
    lines.append("| subject | hand L x W (cm) | " + " | ".join(SCENARIOS[c] for c in cols) + " |")
    lines.append("|---|---|" + "---|" * len(cols))
    for sid, row in report["subjects"].items():
        cells = [fmt(row["scenarios"].get(str(c), {}).get("mean_deg")) for c in cols]
        lines.append(f"| {sid} | {row['hand_length_cm']:.1f} x {row['hand_width_cm']:.1f} | " + " | ".join(cells) + " |")
    lines.append("| **average** | | " + " | ".join(fmt(report["average"].get(str(c))) for c in cols) + " |")
    lines.append("")
    lines.append("Per DoF (degrees, averaged over subjects):")
    lines.append("")
    lines.append("| DoF | " + " | ".join(SCENARIOS[c] for c in cols) + " |")
    lines.append("|---|" + "---|" * len(cols))
    for dof in report["dof_names"]:
        lines.append(f"| {dof} | " + " | ".join(fmt(report["per_dof_average"].get(str(c), {}).get(dof))
                                                 for c in cols) + " |")
    if report.get("finetune_sweep"):
        lines.append("")
        lines.append("Fine-tuning learning rate (average over subjects; batch "
                     f"{cfg['finetune_batch']}):")
        lines.append("")
        lines.append("| column | lr | mean error (deg) | mean best epoch |")
        lines.append("|---|---|---|---|")
        for entry in report["finetune_sweep"]:
            lines.append(f"| {SCENARIOS[entry['scenario']]} | {entry['lr']:g} | {fmt(entry['mean_deg'])} | "
                         f"{entry['mean_best_epoch']:.1f} |")
    if report.get("ablation"):
        ab = report["ablation"]
        lines.append("")
        lines.append(f"Sensor ablation (Fig. 5.10; scenario {ab['scenario']}, excluded cells' inputs zeroed in "
                     "training and testing):")
        lines.append("")
        lines.append("| cells | categories | mean error (deg) |")
        lines.append("|---|---|---|")
        for stage in ab["stages"]:
            lines.append(f"| {stage['cells']} | {stage['name']} | {fmt(stage['mean_deg'])} |")
    lines.append("")
    lines.append(f"Wall time: {report['seconds'] / 60:.1f} min ({cfg['threads']} torch threads).")
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="dataset directory (proprio sim-glove --out DIR)")
    p.add_argument("--model", choices=models.MODEL_KINDS, default="unet")
    p.add_argument("--subjects", help="evaluate (and train generic models on) these subject ids only (default: all)")
    p.add_argument("--test-subjects", help="rows: evaluate only these subject ids (default: all of --subjects); "
                                           "generic models still train on all other subjects")
    p.add_argument("--scenarios", default="1,2,3,4,5,6",
                   help="columns to compute (default 1,2,3,4,5,6; 6 = (5b) fine-tuned on the same donning)")
    p.add_argument("--test-fraction", type=float, default=0.5,
                   help="tail of the last session's task phase used for testing (default 0.5)")
    p.add_argument("--max-train-frames", type=int, default=60000,
                   help="subsample each training set to at most this many frames (default 60000; 0 = all)")
    p.add_argument("--val-fraction", type=float, default=0.1)
    p.add_argument("--unet-width", type=int, default=16)
    p.add_argument("--fcn-hidden", default="384,384,384,192")
    p.add_argument("--finetune-minutes", type=float, default=5.0)
    p.add_argument("--finetune-lr", default=f"{ft.DEFAULT_LR:g}",
                   help="fine-tuning learning rate; a comma-separated list adds a sweep table (first = column 5)")
    p.add_argument("--finetune-batch", type=int, default=ft.DEFAULT_BATCH)
    p.add_argument("--finetune-epochs", type=int, default=30)
    p.add_argument("--ablation", action="store_true", help="also run the 14 -> 44 cell ablation (Fig. 5.10)")
    p.add_argument("--ablation-scenario", type=int, choices=[2, 4], default=2,
                   help="scenario the ablation retrains (default 2: personalised inter-session)")
    p.add_argument("--layout", help="layout TOML for cell categories when meta.json has none")
    p.add_argument("--out-json", required=True)
    p.add_argument("--out-md", required=True)
    p.add_argument("--verbose", action="store_true", help="per-epoch progress")
    train.add_training_arguments(p, epochs=40, batch=256, lr=2e-4, patience=6)
    a = p.parse_args(argv)
    log = (lambda *_: None) if a.quiet else (lambda *m: print(*m, flush=True))
    try:
        data = ds.Dataset(a.data)
        scenarios = training.parse_int_list(a.scenarios, "--scenarios")
        if not scenarios or any(c not in SCENARIOS for c in scenarios):
            raise ValueError(f"--scenarios '{a.scenarios}': expected numbers 1-6")
        lrs = parse_lrs(a.finetune_lr)
        wanted = training.parse_int_list(a.subjects, "--subjects")
        subjects = [s for s in data.subjects() if wanted is None or s in wanted]
        if wanted and set(wanted) - set(subjects):
            raise ValueError(f"--subjects: {sorted(set(wanted) - set(subjects))} not in the dataset "
                             f"(subjects: {data.subjects()})")
        rows = training.parse_int_list(a.test_subjects, "--test-subjects") or subjects
        if set(rows) - set(subjects):
            raise ValueError(f"--test-subjects: {sorted(set(rows) - set(subjects))} not among the subjects {subjects}")
        if len(subjects) < 2 and any(c in (3, 4, 5, 6) for c in scenarios):
            raise ValueError("generic scenarios (3-6) need at least 2 subjects")
        if not 0.0 < a.test_fraction < 1.0:
            raise ValueError(f"--test-fraction {a.test_fraction}: expected 0 < f < 1")
        categories = cell_categories(data, a.layout) if a.ablation else None
        if a.ablation and categories is None:
            raise ValueError("--ablation needs cell categories: meta.json 'cell_categories' or --layout FILE.toml")
        for d in (os.path.dirname(os.path.abspath(a.out_json)), os.path.dirname(os.path.abspath(a.out_md))):
            os.makedirs(d, exist_ok=True)
        ev = Evaluator(data, a, log)
    except (ValueError, OSError, ds.DatasetError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    started = time.time()
    report = {
        "config": {"data": a.data, "layout": data.layout_name, "model": a.model,
                   "parameters": models.parameter_count(models.build_model(
                       a.model, unet_width=a.unet_width, fcn_hidden=training.parse_int_list(a.fcn_hidden, "h"))),
                   "epochs": a.epochs, "batch": a.batch, "lr": a.lr, "seed": a.seed, "threads": a.threads,
                   "test_fraction": a.test_fraction, "max_train_frames": a.max_train_frames,
                   "finetune_minutes": a.finetune_minutes, "finetune_lrs": lrs, "finetune_batch": a.finetune_batch,
                   "finetune_epochs": a.finetune_epochs, "subjects": subjects, "test_subjects": rows},
        "scenarios": scenarios, "dof_names": [n for n in data.output_grid if n is not None],
        "subjects": {}, "notes": "Simulated accuracy is not real-world accuracy.",
    }
    sweep = {(column, lr): [] for column in (5, 6) for lr in lrs}
    ablation = None
    if a.ablation:
        ablation = {"scenario": a.ablation_scenario, "stages": [
            {"name": name, "categories": cats, "cells": int(sum(c in cats for c in categories)), "per_subject": {}}
            for name, cats in ABLATION_STAGES]}

    for subject in rows:
        plan = subject_plan(data, subject, a.test_fraction, a.finetune_minutes)
        sess = data.sessions[plan["test_session"]]
        row = {"hand_length_cm": 100 * float(sess.get("hand_length_m", float("nan"))),
               "hand_width_cm": 100 * float(sess.get("hand_width_m", float("nan"))),
               "test_session": plan["test_session"], "test_frames": int(len(plan["test"])), "scenarios": {}}
        report["subjects"][str(subject)] = row
        log(f"subject {subject}: sessions {plan['sessions']}, testing on {len(plan['test'])} frames of session "
            f"{plan['test_session']}")
        test = plan["test"]
        if 1 in scenarios and len(plan["intra_train"]) > 10:
            m, r = ev.train_model(plan["intra_train"], "session", label=f"s{subject} intra")
            row["scenarios"]["1"] = ev._entry(ev.test(m, test, "session"), r)
        if (2 in scenarios or (ablation and a.ablation_scenario == 2)) and len(plan["inter_train"]) > 10:
            m, r = ev.train_model(plan["inter_train"], "session", label=f"s{subject} inter")
            if 2 in scenarios:
                row["scenarios"]["2"] = ev._entry(ev.test(m, test, "session"), r)
            if ablation and a.ablation_scenario == 2:
                ablation["stages"][-1]["per_subject"][str(subject)] = ev.test(m, test, "session")["mean_deg"]
        others = [s for s in subjects if s != subject]
        generic_frames = data.frames(train.select_sessions(data, subjects=others)) if others else None
        if 3 in scenarios and generic_frames is not None:
            gmin, gmax = data.global_calibration(generic_frames)
            m, r = ev.train_model(generic_frames, "global", gmin, gmax, label=f"s{subject} generic w/o calib")
            row["scenarios"]["3"] = ev._entry(ev.test(m, test, "global", gmin, gmax), r)
        if any(c in scenarios for c in (4, 5, 6)) or (ablation and a.ablation_scenario == 4):
            m, r = ev.train_model(generic_frames, "session", label=f"s{subject} generic w calib")
            generic_errors = ev.test(m, test, "session")
            log(f"  [s{subject} generic w calib] test {generic_errors['mean_deg']:.2f} deg")
            if 4 in scenarios:
                row["scenarios"]["4"] = ev._entry(generic_errors, r)
            if ablation and a.ablation_scenario == 4:
                ablation["stages"][-1]["per_subject"][str(subject)] = generic_errors["mean_deg"]
            generic_state = {k: v.clone() for k, v in m.state_dict().items()}
            tunings = []
            if 5 in scenarios and len(plan["personal"]) > 10:
                tunings.append((5, plan["personal"], plan["personal_sessions"], "other donning"))
            if 6 in scenarios and len(plan["intra_train"]) > 10:
                tuned_frames = ft.personal_frames_of(data, plan["intra_train"], a.finetune_minutes)
                tunings.append((6, tuned_frames, [plan["test_session"]], "same donning"))
            for column, personal, personal_sessions, what in tunings:
                for i, lr in enumerate(lrs):
                    m.load_state_dict(generic_state)
                    training.configure_torch(ev.cfg.threads, ev.cfg.seed)
                    cfg = training.TrainConfig(epochs=a.finetune_epochs, batch=a.finetune_batch, lr=lr,
                                               optimizer=a.optimizer, patience=5, seed=a.seed, threads=a.threads)
                    fr = ft.finetune(m, data, personal, cfg, "session", log=log if a.verbose else None,
                                     label=f"s{subject} finetune {what} lr {lr:g}")
                    errors = ev.test(m, test, "session")
                    log(f"  [s{subject} finetune {what} lr {lr:g}] best epoch {fr['best_epoch']}, personal "
                        f"validation {fr['val_deg_before']:.2f} -> {fr['best_val_deg']:.2f} deg, "
                        f"test {errors['mean_deg']:.2f} deg")
                    sweep[(column, lr)].append((errors["mean_deg"], fr["best_epoch"]))
                    if i == 0:
                        row["scenarios"][str(column)] = ev._entry(
                            errors, fr, {"lr": lr, "best_epoch": fr["best_epoch"], "personal_sessions": personal_sessions,
                                         "personal_frames": int(len(personal))})
        if ablation:
            for stage in ablation["stages"][:-1]:
                cell_mask = np.array([c in stage["categories"] for c in categories])
                frames = plan["inter_train"] if a.ablation_scenario == 2 else generic_frames
                if a.ablation_scenario == 2 and len(frames) <= 10:
                    continue
                m, _ = ev.train_model(frames, "session", cell_mask=cell_mask,
                                      label=f"s{subject} ablation {stage['cells']} cells")
                stage["per_subject"][str(subject)] = ev.test(m, test, "session", cell_mask=cell_mask)["mean_deg"]
        for c, entry in sorted(row["scenarios"].items()):
            log(f"  scenario {c}: {entry['mean_deg']:.2f} deg")

    report["average"] = {}
    report["per_dof_average"] = {}
    for c in scenarios:
        entries = [row["scenarios"][str(c)] for row in report["subjects"].values() if str(c) in row["scenarios"]]
        report["average"][str(c)] = float(np.mean([e["mean_deg"] for e in entries])) if entries else None
        report["per_dof_average"][str(c)] = {
            dof: float(np.mean([e["per_dof_deg"][dof] for e in entries])) for dof in report["dof_names"]} \
            if entries else {}
    if any(c in scenarios for c in (5, 6)):
        report["finetune_sweep"] = [
            {"scenario": column, "lr": lr, "mean_deg": float(np.mean([v[0] for v in vals])) if vals else None,
             "mean_best_epoch": float(np.mean([v[1] for v in vals])) if vals else float("nan"),
             "subjects": len(vals)} for (column, lr), vals in sweep.items() if column in scenarios]
    if ablation:
        for stage in ablation["stages"]:
            values = list(stage["per_subject"].values())
            stage["mean_deg"] = float(np.mean(values)) if values else None
        report["ablation"] = ablation
    report["seconds"] = time.time() - started
    with open(a.out_json, "w", encoding="utf-8") as f:
        json.dump(report, f, indent=1)
        f.write("\n")
    with open(a.out_md, "w", encoding="utf-8") as f:
        f.write(markdown(report))
    log(f"wrote {a.out_json} and {a.out_md} in {report['seconds'] / 60:.1f} min")
    for c in scenarios:
        log(f"  {SCENARIOS[c]}: {fmt(report['average'][str(c)])} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
