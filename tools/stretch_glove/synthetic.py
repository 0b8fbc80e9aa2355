#!/usr/bin/python3
"""A small synthetic stretch-glove dataset in the format of `proprio sim-glove --out DIR`.

For the tests and tiny runs of the training tools only: it is a quick stand-in
with a simple physical flavour (C/C0 = (A/A0)^2 of cells stretched by nearby
joints, per-subject hand size, per-donning gain/offset, noise), NOT the
simulator. Real experiments use `proprio sim-glove`.

  /usr/bin/python3 tools/stretch_glove/synthetic.py --out /tmp/glove_data --subjects 3 --sessions 2 --minutes 0.5
"""

import argparse
import json
import os
import sys

import numpy as np

DOF_NAMES = [
    "thumb_cmc_flexion", "thumb_cmc_abduction", "thumb_mcp_flexion", "thumb_ip_flexion",
    "index_mcp_flexion", "index_mcp_abduction", "index_pip_flexion", "index_dip_flexion",
    "middle_mcp_flexion", "middle_mcp_abduction", "middle_pip_flexion", "middle_dip_flexion",
    "ring_mcp_flexion", "ring_mcp_abduction", "ring_pip_flexion", "ring_dip_flexion",
    "little_mcp_flexion", "little_mcp_abduction", "little_pip_flexion", "little_dip_flexion",
]
FINGERS = ["thumb", "index", "middle", "ring", "little"]

# Output grid: row = finger, columns = [abduction, base flexion, middle flexion, distal flexion, empty].
OUTPUT_GRID = []
for _f in FINGERS:
    if _f == "thumb":
        OUTPUT_GRID += ["thumb_cmc_abduction", "thumb_cmc_flexion", "thumb_mcp_flexion", "thumb_ip_flexion", None]
    else:
        OUTPUT_GRID += [f"{_f}_mcp_abduction", f"{_f}_mcp_flexion", f"{_f}_pip_flexion", f"{_f}_dip_flexion", None]

# Rough joint ranges (rad) the motion explores.
RANGES = {
    "thumb_cmc_flexion": (-0.2, 0.7), "thumb_cmc_abduction": (0.0, 0.9),
    "thumb_mcp_flexion": (0.0, 0.9), "thumb_ip_flexion": (-0.1, 1.2),
}
for _f in FINGERS[1:]:
    RANGES[f"{_f}_mcp_flexion"] = (-0.2, 1.5)
    RANGES[f"{_f}_mcp_abduction"] = (-0.3, 0.3)
    RANGES[f"{_f}_pip_flexion"] = (0.0, 1.8)
    RANGES[f"{_f}_dip_flexion"] = (0.0, 1.2)


def _cell(name, category, layer, row, col, dofs):
    """dofs: {dof name: stretch per radian} (the cell's area stretch model)."""
    return {"name": name, "category": category, "layer": layer, "row": row, "col": col, "dofs": dofs}


def synthetic_layout():
    """44 cells in the thesis's four categories (14 joint, 4 abduction, 11 perpendicular, 15 dorsum)."""
    cells = []
    # Joint ("along") cells: layer 0, row 0 distal .. row 2 proximal, column = finger.
    cells.append(_cell("thumb_ip_along", "joint", 0, 0, 0, {"thumb_ip_flexion": 0.20, "thumb_mcp_flexion": 0.04}))
    cells.append(_cell("thumb_mcp_along", "joint", 0, 1, 0, {"thumb_mcp_flexion": 0.20, "thumb_cmc_flexion": 0.05}))
    for c, f in enumerate(FINGERS[1:], start=1):
        cells.append(_cell(f"{f}_dip_along", "joint", 0, 0, c, {f"{f}_dip_flexion": 0.18, f"{f}_pip_flexion": 0.04}))
        cells.append(_cell(f"{f}_pip_along", "joint", 0, 1, c, {f"{f}_pip_flexion": 0.22, f"{f}_mcp_flexion": 0.05}))
        cells.append(_cell(f"{f}_mcp_along", "joint", 0, 2, c, {f"{f}_mcp_flexion": 0.25, f"{f}_pip_flexion": 0.03}))
    # Abduction (web) cells: layer 1, row 2.
    pairs = [("thumb", "index"), ("index", "middle"), ("middle", "ring"), ("ring", "little")]
    for c, (a, b) in enumerate(pairs, start=1):
        if a == "thumb":
            dofs = {"thumb_cmc_abduction": 0.25, "index_mcp_abduction": -0.05}
        else:
            dofs = {f"{a}_mcp_abduction": 0.3, f"{b}_mcp_abduction": -0.3, f"{a}_mcp_flexion": 0.02}
        cells.append(_cell(f"{a}_{b}_web", "abduction", 1, 2, c, dofs))
    # Perpendicular ("across") cells: finger volume, bulging with proximal flexion.
    cells.append(_cell("thumb_distal_across", "perpendicular", 1, 0, 0, {"thumb_ip_flexion": 0.03, "thumb_mcp_flexion": 0.05}))
    cells.append(_cell("thumb_proximal_across", "perpendicular", 1, 1, 0, {"thumb_mcp_flexion": 0.06, "thumb_cmc_flexion": 0.04}))
    cells.append(_cell("thumb_metacarpal_across", "perpendicular", 1, 2, 0, {"thumb_cmc_flexion": 0.06, "thumb_cmc_abduction": 0.04}))
    for c, f in enumerate(FINGERS[1:], start=1):
        cells.append(_cell(f"{f}_intermediate_across", "perpendicular", 1, 0, c, {f"{f}_pip_flexion": 0.05, f"{f}_dip_flexion": 0.03}))
    for c, f in enumerate(FINGERS[1:], start=1):
        cells.append(_cell(f"{f}_proximal_across", "perpendicular", 1, 1, c, {f"{f}_mcp_flexion": 0.06, f"{f}_pip_flexion": 0.03}))
    # Dorsum grid: along (layer 0) and across (layer 1) cells on the back of the hand.
    dorsum_along = [(2, 0), (3, 0), (3, 1), (3, 2), (3, 3), (3, 4), (4, 0), (4, 1)]
    for k, (r, c) in enumerate(dorsum_along):
        f = FINGERS[max(1, min(4, c))]
        cells.append(_cell(f"dorsum_along_{k}", "dorsum", 0, r, c,
                           {f"{f}_mcp_flexion": 0.08 / (r - 1), "thumb_cmc_flexion": 0.03 if c <= 1 else 0.0}))
    dorsum_across = [(3, 0), (3, 1), (3, 2), (3, 3), (3, 4), (4, 0), (4, 1)]
    for k, (r, c) in enumerate(dorsum_across):
        f = FINGERS[max(1, min(4, c))]
        cells.append(_cell(f"dorsum_across_{k}", "dorsum", 1, r, c,
                           {f"{f}_mcp_abduction": 0.05, f"{f}_mcp_flexion": 0.03, "thumb_cmc_abduction": 0.03 if c <= 1 else 0.0}))
    assert len(cells) == 44
    return cells


def _smooth_motion(rng, frames, rate_hz, wide):
    """Joint angles [frames, 20]: sums of slow sinusoids in each DoF's range, anatomically coupled."""
    t = np.arange(frames) / rate_hz
    angles = np.zeros((frames, len(DOF_NAMES)), dtype=np.float64)
    shared = np.zeros((frames, 3))
    for k in range(3):  # whole-hand grasp components: fingers move together
        f = rng.uniform(0.05, 0.4) * (2.0 if wide else 1.0)
        shared[:, k] = np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    for d, name in enumerate(DOF_NAMES):
        lo, hi = RANGES[name]
        own = np.zeros(frames)
        for _ in range(3):
            f = rng.uniform(0.05, 0.6) * (2.0 if wide else 1.0)
            own += rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        own /= 1.5
        grasp = shared @ rng.uniform(0.2, 0.6, size=3) if "flexion" in name else 0.0
        u = np.tanh(0.8 * own + 0.6 * grasp) * (1.15 if wide else 0.9)
        angles[:, d] = lo + (hi - lo) * 0.5 * (np.clip(u, -1, 1) + 1)
    for f in FINGERS[1:]:  # DIP follows PIP (about 2/3), with its own deviation
        pip = angles[:, DOF_NAMES.index(f"{f}_pip_flexion")]
        dip = DOF_NAMES.index(f"{f}_dip_flexion")
        angles[:, dip] = 0.5 * angles[:, dip] + 0.5 * (2.0 / 3.0) * pip
    return angles.astype(np.float32)


def _cell_capacitance(cells, angles, hand_scale, gains, offsets, rng, noise_pf):
    """C = C0 (A/A0)^2 with area stretch 1 + sum_d k_d * angle_d (a bigger hand stretches more)."""
    n = angles.shape[0]
    out = np.zeros((n, len(cells)), dtype=np.float64)
    for i, cell in enumerate(cells):
        stretch = np.ones(n)
        for dof, k in cell["dofs"].items():
            stretch += hand_scale * k * angles[:, DOF_NAMES.index(dof)]
        pre = 1.0 + 0.05 * (hand_scale - 1.0)  # bigger hands pre-stretch the glove
        rest = 20.0 if cell["layer"] == 0 else 12.0
        out[:, i] = rest * gains[i] * (pre * np.maximum(stretch, 0.5)) ** 2 + offsets[i]
    out += rng.normal(0.0, noise_pf, size=out.shape)
    return out.astype(np.float32)


def _running_median_min_max(x, window=20):
    if x.shape[0] < window:
        med = np.median(x, axis=0, keepdims=True)
    else:
        view = np.lib.stride_tricks.sliding_window_view(x, window, axis=0)
        med = np.median(view, axis=-1)
    return med.min(axis=0), med.max(axis=0)


def generate(out_dir, subjects=3, sessions=2, minutes=0.5, exploration_seconds=10.0, seed=1,
             sessions_per_donning=1, frame_rate_hz=60.0, noise_pf=0.05):
    rng_root = np.random.SeedSequence(seed)
    cells = synthetic_layout()
    os.makedirs(out_dir, exist_ok=True)
    all_cells, all_angles, all_session, all_subject, all_phase = [], [], [], [], []
    cal_min, cal_max, session_meta = [], [], []
    subject_seqs = rng_root.spawn(subjects)
    for s in range(subjects):
        srng = np.random.default_rng(subject_seqs[s])
        hand_length = float(srng.uniform(0.17, 0.205))
        hand_width = float(srng.uniform(0.08, 0.10))
        hand_scale = hand_length / 0.19
        gains = offsets = None
        for k in range(sessions):
            donning = k // sessions_per_donning
            if k % sessions_per_donning == 0:
                gains = srng.normal(1.0, 0.06, size=len(cells))
                offsets = srng.normal(0.0, 0.4, size=len(cells))
            n_explore = int(round(exploration_seconds * frame_rate_hz))
            n_task = int(round(minutes * 60.0 * frame_rate_hz))
            angles = np.concatenate([_smooth_motion(srng, n_explore, frame_rate_hz, wide=True),
                                     _smooth_motion(srng, n_task, frame_rate_hz, wide=False)])
            caps = _cell_capacitance(cells, angles, hand_scale, gains, offsets, srng, noise_pf)
            lo, hi = _running_median_min_max(caps[:n_explore])
            hi = np.maximum(hi, lo + 1e-3)
            index = len(session_meta)
            session_meta.append({"subject": s, "session": k, "donning": donning, "frames": n_explore + n_task,
                                 "hand_length_m": hand_length, "hand_width_m": hand_width})
            all_cells.append(caps)
            all_angles.append(angles)
            all_session.append(np.full(len(caps), index, dtype=np.int32))
            all_subject.append(np.full(len(caps), s, dtype=np.int32))
            all_phase.append(np.concatenate([np.zeros(n_explore, np.uint8), np.ones(n_task, np.uint8)]))
            cal_min.append(lo)
            cal_max.append(hi)
    meta = {
        "layout": "synthetic-44",
        "cell_count": len(cells),
        "frame_rate_hz": frame_rate_hz,
        "output_grid": OUTPUT_GRID,
        "input_grid_index": [c["layer"] * 25 + c["row"] * 5 + c["col"] for c in cells],
        "dof_names": DOF_NAMES,
        "cell_names": [c["name"] for c in cells],
        "cell_categories": [c["category"] for c in cells],
        "sessions": session_meta,
        "units": "cells: recovered capacitance, pF; angles: radians",
        "generator": {"name": "tools/stretch_glove/synthetic.py", "seed": seed, "subjects": subjects,
                      "sessions": sessions, "minutes": minutes, "exploration_seconds": exploration_seconds,
                      "sessions_per_donning": sessions_per_donning, "noise_pf": noise_pf},
    }
    with open(os.path.join(out_dir, "meta.json"), "w", encoding="utf-8") as f:
        json.dump(meta, f, indent=1)
    np.save(os.path.join(out_dir, "cells.npy"), np.concatenate(all_cells))
    np.save(os.path.join(out_dir, "angles.npy"), np.concatenate(all_angles))
    np.save(os.path.join(out_dir, "session.npy"), np.concatenate(all_session))
    np.save(os.path.join(out_dir, "subject.npy"), np.concatenate(all_subject))
    np.save(os.path.join(out_dir, "phase.npy"), np.concatenate(all_phase))
    np.save(os.path.join(out_dir, "calib_min.npy"), np.asarray(cal_min, dtype=np.float32))
    np.save(os.path.join(out_dir, "calib_max.npy"), np.asarray(cal_max, dtype=np.float32))
    return out_dir


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="dataset directory to write")
    p.add_argument("--subjects", type=int, default=3)
    p.add_argument("--sessions", type=int, default=2, help="sessions per subject")
    p.add_argument("--sessions-per-donning", type=int, default=1,
                   help="consecutive sessions that share one donning (glove kept on); 1 = each session a new donning")
    p.add_argument("--minutes", type=float, default=0.5, help="task motion per session")
    p.add_argument("--exploration-seconds", type=float, default=10.0, help="calibration exploration per session")
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args(argv)
    if a.subjects < 1 or a.sessions < 1 or a.minutes <= 0 or a.exploration_seconds <= 0 or a.sessions_per_donning < 1:
        p.error("--subjects, --sessions, --sessions-per-donning, --minutes and --exploration-seconds must be positive")
    generate(a.out, a.subjects, a.sessions, a.minutes, a.exploration_seconds, a.seed, a.sessions_per_donning)
    print(f"wrote {a.out}: {a.subjects} subjects x {a.sessions} sessions (synthetic, for tests only)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
