#!/usr/bin/python3
"""Evaluates stretch-array regressors (in PyTorch, not through ONNX) by per-marker Euclidean
error in millimetres (mean / std / max over all test frames and markers), against the true
marker positions and against the labelled ones. Four modes:

  model      one trained model (train.py --out DIR) on a dataset's test sessions
               evaluate.py model MODEL_DIR DATASET [--test-sessions split=test] [--out OUT]
  table41    Table 4.1: trains dnn, svm and lr on each dataset's training sessions and tests
             them on its same-donning test sessions; one row block per dataset (motion)
               evaluate.py table41 BALLOON BICEPS ELBOW WRIST FOREARM --out OUT [--tiny]
  table42    Table 4.2: trains on the wrist dataset's frames with alpha < gamma or alpha > beta
             for the thesis's (gamma, beta) rows (or --rows), fixed test set; frames, mean, max
               evaluate.py table42 WRIST --out OUT [--model dnn] [--rows "60:max,20:30,min:20"]
  redonning  trains on donning 0 and tests on a donning-0 test session and on re-donned ones
               evaluate.py redonning WRIST --out OUT [--model dnn]

Each mode writes OUT/<mode>.json and OUT/<mode>.md (OUT defaults to the current directory for
`model`, which prints its table). Training options are train.py's (--tiny, --epochs, ...).
The thesis's numbers are shown next to ours for reference; ours come from simulated data.
"""

import argparse
import json
import math
import os
import sys
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import array_dataset as ads  # noqa: E402
import regressors  # noqa: E402
import train as train_tool  # noqa: E402

# Glauser 2019, Table 4.1: (mean, std, max) mm per motion and model.
THESIS_TABLE_41 = {
    "balloon": {"lr": (3.59, 1.90, 12.84), "svm": (3.22, 2.73, 25.05), "dnn": (2.75, 1.86, 12.85)},
    "biceps": {"lr": (7.64, 5.06, 53.00), "svm": (6.86, 5.18, 52.24), "dnn": (3.85, 2.39, 25.81)},
    "elbow": {"lr": (7.65, 3.31, 39.95), "svm": (6.73, 5.26, 59.79), "dnn": (3.46, 2.48, 30.82)},
    "wrist": {"lr": (12.8, 4.99, 71.89), "svm": (4.36, 2.71, 44.12), "dnn": (3.51, 2.14, 27.22)},
    "forearm": {"lr": (10.64, 3.94, 52.03), "svm": (4.38, 2.30, 32.11), "dnn": (4.02, 2.66, 38.52)},
}
# Table 4.2: (gamma, beta, frames, mean, max); None = alpha_min / alpha_max (that side keeps nothing).
THESIS_TABLE_42 = [
    (None, None, 8799, 3.51, 27.22), (60, None, 8668, 3.14, 28.40), (40, None, 7335, 3.40, 49.20),
    (30, None, 5777, 4.07, 50.55), (20, None, 3229, 6.59, 76.96), (20, 30, 6251, 3.35, 26.45),
    (20, 40, 4693, 3.89, 31.31), (None, 20, 5570, 3.41, 35.76), (None, 30, 3022, 4.67, 47.76),
    (None, 40, 1464, 7.38, 52.50),
]
# Sec. 4.5.2: wrist, in-session vs out-of-session (re-donned) mean (max) mm.
THESIS_REDONNING = {"same": (4.06, 38.28), "redonned": (6.80, 47.22)}
MODEL_LABEL = {"dnn": "ours (DNN)", "svm": "SVM (RBF kernel ridge)", "lr": "LR"}


def keep_expression(gamma, beta, pose_name="alpha"):
    """'alpha<gamma or alpha>beta' with open ends dropped; None when every frame is kept (row 1)."""
    if gamma is None and beta is None:
        return None
    parts = ([f"{pose_name}<{gamma:g}"] if gamma is not None else []) + \
            ([f"{pose_name}>{beta:g}"] if beta is not None else [])
    return " or ".join(parts)


def parse_rows(text):
    """'60:max,20:30,min:20' -> [(60, None), (20, 30), (None, 20)]; 'thesis' -> Table 4.2's rows."""
    if text in (None, "", "thesis"):
        return [(g, b) for g, b, *_ in THESIS_TABLE_42]
    rows = []
    for item in text.split(","):
        g, sep, b = item.partition(":")
        try:
            if not sep:
                raise ValueError
            rows.append((None if g.strip() == "min" else float(g), None if b.strip() == "max" else float(b)))
        except ValueError:
            raise ValueError(f"--rows '{text}': expected gamma:beta pairs like 60:max,20:30,min:20") from None
    return rows


def _fmt(v, digits=2):
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def _write(out_dir, name, result, markdown):
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, f"{name}.json"), "w", encoding="utf-8") as f:
        json.dump(result, f, indent=1)
        f.write("\n")
    with open(os.path.join(out_dir, f"{name}.md"), "w", encoding="utf-8") as f:
        f.write(markdown)
    print(markdown, end="")


def same_donning_test_sessions(data, train_sessions, selector=None):
    """Test sessions (split=test, or the selector) worn in a donning the training sessions used."""
    candidates = ads.select_sessions(data, selector or "split=test")
    donnings = {data.sessions[s].get("donning", 0) for s in train_sessions}
    return [s for s in candidates if data.sessions[s].get("donning", 0) in donnings and s not in train_sessions]


def redonned_test_sessions(data, train_sessions, selector=None):
    candidates = ads.select_sessions(data, selector or "split=test")
    donnings = {data.sessions[s].get("donning", 0) for s in train_sessions}
    return [s for s in candidates if data.sessions[s].get("donning", 0) not in donnings]


# -- modes ------------------------------------------------------------------------

def mode_model(a, log):
    model, sidecar = train_tool.load(a.model_dir)
    data = ads.ArrayDataset(a.dataset)
    if sidecar.get("cell_count") != data.cell_count or sidecar.get("marker_count") != data.marker_count:
        raise ValueError(f"{a.model_dir}: model has {sidecar.get('cell_count')} cells and {sidecar.get('marker_count')} "
                         f"markers, the dataset {data.cell_count} and {data.marker_count}")
    sessions = ads.select_sessions(data, a.test_sessions)
    if not sessions:
        raise ValueError(f"--test-sessions '{a.test_sessions}' selects no session")
    result = {"model": os.path.abspath(a.model_dir), "kind": sidecar.get("kind"), "dataset": os.path.abspath(a.dataset),
              "all": train_tool.test_errors(data, model, sessions),
              "per_session": {data.sessions[s].get("name", str(s)): train_tool.test_errors(data, model, [s])
                              for s in sessions}}
    md = ["| test sessions | frames | mean | std | max | mean vs labelled |", "|---|---|---|---|---|---|"]
    for label, r in [("all", result["all"])] + list(result["per_session"].items()):
        t = r["truth"]
        md.append(f"| {label} | {r['frames']} | {_fmt(t['mean'])} | {_fmt(t['std'])} | {_fmt(t['max'])} | "
                  f"{_fmt(r['labelled']['mean'])} |")
    _write(a.out or ".", "model_eval", result, f"Marker error (mm) of {result['kind']} model {a.model_dir}\n\n"
           + "\n".join(md) + "\n")


def mode_table41(a, log):
    kinds = [k.strip() for k in a.models.split(",")]
    for k in kinds:
        if k not in regressors.KINDS:
            raise ValueError(f"--models: unknown kind '{k}' (expected {', '.join(regressors.KINDS)})")
    datasets = [ads.ArrayDataset(d) for d in a.datasets]  # all checked before any training
    rows = []
    for di, data in enumerate(datasets):
        train_s = ads.select_sessions(data, a.train_sessions)
        test_s = same_donning_test_sessions(data, train_s, a.test_sessions)
        if not train_s or not test_s:
            raise ValueError(f"{data.directory}: needs training sessions and same-donning test sessions "
                             f"(got {train_s} and {test_s})")
        for kind in kinds:
            t0 = time.time()
            model, info, train_f, val_f = train_tool.train(data, kind, train_s, a, None, log)
            errors = train_tool.test_errors(data, model, test_s)
            rows.append({"dataset": data.directory, "motion": data.motion, "kind": kind, "train_frames": int(len(train_f)),
                         "val_error_mm": info.get("val_error_mm"), "epochs": info.get("epochs_run"),
                         "seconds": time.time() - t0, "test": errors})
            if a.save_models:
                out = os.path.join(a.out, "models", f"{di}_{data.motion}_{kind}")
                train_tool.save(out, model, train_tool.sidecar_for(data, kind, model, info, train_s, train_f,
                                                                   val_f, None, errors))
    md = ["| Dataset | Model | mean | std | max | mean vs labelled | train / test frames | thesis mean | thesis std | thesis max |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t, ref = r["test"]["truth"], THESIS_TABLE_41.get(r["motion"], {}).get(r["kind"], (None, None, None))
        md.append(f"| {r['motion']} | {MODEL_LABEL[r['kind']]} | {_fmt(t['mean'])} | {_fmt(t['std'])} | {_fmt(t['max'])} | "
                  f"{_fmt(r['test']['labelled']['mean'])} | {r['train_frames']} / {r['test']['frames']} | "
                  f"{_fmt(ref[0])} | {_fmt(ref[1])} | {_fmt(ref[2])} |")
    head = ("Table 4.1 (simulated): marker error in mm against the true marker positions, test sessions of the "
            "training donning. Thesis columns: Glauser 2019 Table 4.1 (real data).\n\n")
    _write(a.out, "table41", {"rows": rows, "options": vars(a)}, head + "\n".join(md) + "\n")


def mode_table42(a, log):
    data = ads.ArrayDataset(a.dataset)
    train_s = ads.select_sessions(data, a.train_sessions)
    test_s = same_donning_test_sessions(data, train_s, a.test_sessions)
    if not train_s or not test_s:
        raise ValueError(f"{data.directory}: needs training sessions and same-donning test sessions")
    all_frames = data.frames(train_s)
    pose = data.pose[all_frames]
    rows = []
    thesis = {(g, b): (f, m, x) for g, b, f, m, x in THESIS_TABLE_42}
    for gamma, beta in parse_rows(a.rows):
        expr = keep_expression(gamma, beta, data.pose_name)
        kept = int(ads.pose_filter(expr, data.pose_name)(pose).sum()) if expr else len(all_frames)
        row = {"gamma": gamma, "beta": beta, "keep": expr, "frames": kept, "thesis": thesis.get((gamma, beta))}
        if kept < 20:
            row["skipped"] = f"only {kept} training frames"
        else:
            model, info, train_f, _ = train_tool.train(data, a.model, train_s, a, expr, log)
            row.update(train_frames=int(len(train_f)), val_error_mm=info.get("val_error_mm"),
                       test=train_tool.test_errors(data, model, test_s))
        rows.append(row)
    name = data.pose_name
    md = ["| gamma | beta | #frames | mean | max | thesis #frames | thesis mean | thesis max |",
          "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t = r.get("test", {}).get("truth", {})
        th = r["thesis"] or (None, None, None)
        md.append(f"| {_fmt(r['gamma'], 0) if r['gamma'] is not None else name + '_min'} | "
                  f"{_fmt(r['beta'], 0) if r['beta'] is not None else name + '_max'} | {r['frames']} | "
                  f"{_fmt(t.get('mean'))} | {_fmt(t.get('max'))} | {th[0] if th[0] is not None else '-'} | "
                  f"{_fmt(th[1])} | {_fmt(th[2])} |")
    p = data.pose[all_frames]
    head = (f"Table 4.2 (simulated, {MODEL_LABEL[a.model]}): training frames kept where {name} < gamma or "
            f"{name} > beta; fixed test set ({len(data.frames(test_s))} frames). Training {name} spans "
            f"{p.min():.1f} .. {p.max():.1f}. Errors in mm against the true markers.\n\n")
    _write(a.out, "table42", {"rows": rows, "pose_range": [float(p.min()), float(p.max())], "options": vars(a)},
           head + "\n".join(md) + "\n")


def mode_redonning(a, log):
    data = ads.ArrayDataset(a.dataset)
    train_s = ads.select_sessions(data, a.train_sessions)
    same = same_donning_test_sessions(data, train_s, a.test_sessions)
    other = redonned_test_sessions(data, train_s, a.test_sessions)
    if not train_s or not same or not other:
        raise ValueError(f"{data.directory}: re-donning needs training sessions ({train_s}), a test session of the same "
                         f"donning ({same}) and a re-donned test session ({other})")
    model, info, train_f, _ = train_tool.train(data, a.model, train_s, a, None, log)
    result = {"kind": a.model, "train_sessions": data.summary(train_s), "train_frames": int(len(train_f)),
              "same_donning": train_tool.test_errors(data, model, same),
              "redonned": train_tool.test_errors(data, model, other), "thesis": THESIS_REDONNING}
    md = ["| test | sessions | frames | mean | std | max | thesis mean | thesis max |", "|---|---|---|---|---|---|---|---|"]
    for key, label in (("same_donning", "same donning"), ("redonned", "re-donned")):
        r, th = result[key], THESIS_REDONNING["same" if key == "same_donning" else "redonned"]
        names = ", ".join(data.sessions[s].get("name", str(s)) for s in r["sessions"])
        t = r["truth"]
        md.append(f"| {label} | {names} | {r['frames']} | {_fmt(t['mean'])} | {_fmt(t['std'])} | {_fmt(t['max'])} | "
                  f"{_fmt(th[0])} | {_fmt(th[1])} |")
    head = f"Re-donning ({MODEL_LABEL[a.model]}, trained on donning(s) {sorted({data.sessions[s].get('donning', 0) for s in train_s})}), mm:\n\n"
    _write(a.out, "redonning", result, head + "\n".join(md) + "\n")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="mode", required=True)
    m = sub.add_parser("model", help="evaluate one trained model")
    m.add_argument("model_dir")
    m.add_argument("dataset")
    m.add_argument("--test-sessions", default="split=test", help=ads.SELECTOR_HELP)
    m.add_argument("--out", help="directory for model_eval.json/.md (default: current directory)")
    t1 = sub.add_parser("table41", help="Table 4.1: dnn, svm, lr on each dataset")
    t1.add_argument("datasets", nargs="+")
    t1.add_argument("--models", default="lr,svm,dnn", help="kinds, comma-separated (default lr,svm,dnn)")
    t1.add_argument("--save-models", action="store_true", help="also write OUT/models/<dataset>_<kind>/")
    t2 = sub.add_parser("table42", help="Table 4.2: reduced wrist training data")
    t2.add_argument("dataset")
    t2.add_argument("--model", choices=regressors.KINDS, default="dnn")
    t2.add_argument("--rows", default="thesis", help="gamma:beta pairs (min/max for open ends) or 'thesis'")
    rd = sub.add_parser("redonning", help="same-donning vs re-donned test error")
    rd.add_argument("dataset")
    rd.add_argument("--model", choices=regressors.KINDS, default="dnn")
    for sp, train_default in ((t1, "split=train"), (t2, "split=train"), (rd, "split=train&donning=0")):
        sp.add_argument("--out", required=True, help="output directory")
        sp.add_argument("--train-sessions", default=train_default, help=ads.SELECTOR_HELP)
        sp.add_argument("--test-sessions", default="split=test",
                        help="candidate test sessions (default split=test), split by donning: " + ads.SELECTOR_HELP)
        train_tool.add_options(sp)
    a = p.parse_args(argv)
    log = (lambda *_: None) if getattr(a, "quiet", False) or a.mode == "model" else (lambda s: print(s, flush=True))
    try:
        {"model": mode_model, "table41": mode_table41, "table42": mode_table42, "redonning": mode_redonning}[a.mode](a, log)
    except (ValueError, FileNotFoundError, ads.DatasetError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
