#!/usr/bin/python3
"""A synthetic stretch-array dataset in the `proprio sim-array` format (see array_dataset.py),
for tests: a hinge ("wrist") bending by alpha and a bulge, markers on a cylinder, cells whose
ratios are smooth nonlinear functions of (alpha, bulge). The cells -> markers map is
nonlinear (markers move on arcs: sin/cos of alpha; ratios are quadratic in the stretch), so
a linear model cannot fit it and a small network can. Not a physical model.

  /usr/bin/python3 tools/stretch_array/synthetic.py OUT_DIR [--cells 24] [--markers 6] [--seed 1]
"""

import argparse
import json
import os
import sys

import numpy as np

import array_dataset as ads

DEFAULT_SESSIONS = (  # (split, donning, frames)
    ("train", 0, 1600),
    ("test", 0, 400),
    ("test", 1, 400),
)


def _smooth_signal(rng, frames, rate_hz, lo, hi):
    """A sum of slow sinusoids mapped to [lo, hi]: a motion that sweeps the range repeatedly."""
    t = np.arange(frames) / rate_hz
    s = np.zeros(frames)
    for _ in range(3):
        f = rng.uniform(0.05, 0.25)
        s += np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) / rng.uniform(1.0, 2.0)
    s = (s - s.min()) / max(s.max() - s.min(), 1e-9)
    return lo + (hi - lo) * s


def generate(directory, cells=24, markers=6, sessions=DEFAULT_SESSIONS, seed=1, rate_hz=8.0, alpha_max_deg=150.0,
             cell_noise=0.002, marker_noise_m=0.0002, redonning_gain=0.03, motion="wrist"):
    rng = np.random.default_rng(seed)
    os.makedirs(directory, exist_ok=True)
    # The sensor: each cell's sensitivity to bending, to the bulge, and their interaction.
    s_bend = rng.uniform(0.0, 0.5, cells)
    s_bulge = rng.uniform(0.0, 0.3, cells)
    s_mix = rng.uniform(-0.2, 0.2, cells)
    # Markers: half on the forearm (x < 0), half on the hand (x > 0), on a cylinder of radius 4 cm.
    u = np.linspace(-0.1, 0.12, markers)
    phi = rng.uniform(0, 2 * np.pi, markers)
    rest = np.stack([u, 0.04 * np.cos(phi), 0.04 * np.sin(phi)], axis=1)

    all_cells, all_markers, all_truth, all_pose, all_session, meta_sessions = [], [], [], [], [], []
    first = 0
    for index, (split, donning, frames) in enumerate(sessions):
        alpha = _smooth_signal(rng, frames, rate_hz, 0.0, alpha_max_deg)
        bulge = _smooth_signal(rng, frames, rate_hz, 0.0, 1.0)
        a = alpha / alpha_max_deg
        stretch = 1.0 + np.outer(a, s_bend) + np.outer(bulge, s_bulge) + np.outer(a * bulge, s_mix)
        ratios = stretch ** 2  # area-like response (eq. 4.4: C/C0 = (A/A0)^2 in area)
        if donning:  # a re-donned sleeve sits slightly differently: per-cell gain offsets
            ratios = ratios * (1.0 + redonning_gain * np.random.default_rng(seed + 1000 * donning).standard_normal(cells))
        ratios = ratios + cell_noise * rng.standard_normal(ratios.shape)
        truth = np.repeat(rest[None], frames, axis=0)
        truth[:, :, 1:] *= (1.0 + 0.15 * bulge)[:, None, None]
        hand = rest[:, 0] > 0
        th = np.radians(alpha)[:, None]
        x, z = truth[:, hand, 0].copy(), truth[:, hand, 2].copy()
        truth[:, hand, 0] = np.cos(th) * x - np.sin(th) * z
        truth[:, hand, 2] = np.sin(th) * x + np.cos(th) * z
        labelled = truth + marker_noise_m * rng.standard_normal(truth.shape)
        all_cells.append(ratios)
        all_markers.append(labelled)
        all_truth.append(truth)
        all_pose.append(alpha)
        all_session.append(np.full(frames, index))
        meta_sessions.append({"name": f"{motion}_{split}_d{donning}_{index}", "motion": motion, "donning": int(donning),
                              "split": split, "first_frame": first, "frames": int(frames), "frames_dropped": 0})
        first += frames

    np.save(os.path.join(directory, "cells.npy"), np.concatenate(all_cells).astype(np.float32))
    np.save(os.path.join(directory, "markers.npy"), np.concatenate(all_markers).astype(np.float32))
    np.save(os.path.join(directory, "markers_truth.npy"), np.concatenate(all_truth).astype(np.float32))
    np.save(os.path.join(directory, "pose.npy"), np.concatenate(all_pose).astype(np.float32))
    np.save(os.path.join(directory, "session.npy"), np.concatenate(all_session).astype(np.int32))
    meta = {
        "format": ads.FORMAT, "version": ads.VERSION, "layout": f"synthetic_{cells}", "cell_count": cells,
        "cell_names": [f"c{i}" for i in range(cells)], "marker_count": markers,
        "marker_names": [f"m{i}" for i in range(markers)], "mesh_vertex_count": 0, "frame_rate_hz": rate_hz,
        "sessions": meta_sessions, "pose_name": "alpha",
        "units": {"cells": "C/C0", "markers": "m", "pose": "deg"},
        "generator": {"tool": "tools/stretch_array/synthetic.py", "seed": seed},
    }
    with open(os.path.join(directory, "meta.json"), "w", encoding="utf-8") as f:  # last: marks completion
        json.dump(meta, f, indent=1)
    return directory


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out")
    p.add_argument("--cells", type=int, default=24)
    p.add_argument("--markers", type=int, default=6)
    p.add_argument("--train-frames", type=int, default=1600)
    p.add_argument("--test-frames", type=int, default=400)
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args(argv)
    generate(a.out, a.cells, a.markers, (("train", 0, a.train_frames), ("test", 0, a.test_frames),
                                         ("test", 1, a.test_frames)), a.seed)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
