#!/usr/bin/python3
"""Stretch-array regression datasets: loading, checks, session selection, pose filters.

A dataset is a directory written by `proprio sim-array` (or synthetic.py for tests):
  meta.json            format "proprio-stretch-array-dataset", version 1, layout, cell_count,
                       cell_names, marker_count, marker_names, mesh_vertex_count, frame_rate_hz,
                       sessions [{name, motion, donning, split, first_frame, frames, frames_dropped}],
                       pose_name, units, generator. Written last: its presence marks a complete dataset.
  cells.npy            float32 [N, C]     capacitance ratio C/C0 per cell (the regressor's input)
  markers.npy          float32 [N, M, 3]  labelled mocap markers, metres, body frame (training target)
  markers_truth.npy    float32 [N, M, 3]  true marker positions (evaluation only)
  vertices_truth.npy   float32 [N, V, 3]  optional; not read here (dense evaluation is C++'s)
  pose.npy             float32 [N]        the motion's pose value (e.g. wrist angle alpha, degrees)
  session.npy          int32   [N]        index into meta.sessions; frames are in session order
"""

import importlib.util
import json
import math
import os
import re

import numpy as np

FORMAT = "proprio-stretch-array-dataset"
VERSION = 1
MOTIONS = ("balloon", "biceps", "elbow", "wrist", "forearm", "flat")
SPLITS = ("train", "test")

_HERE = os.path.dirname(os.path.abspath(__file__))
_GLOVE_DIR = os.path.join(os.path.dirname(_HERE), "stretch_glove")


def load_glove_module(name):
    """A module of tools/stretch_glove, imported under the name stretch_glove_NAME so that
    its generic names (dataset, models, training) cannot shadow ours."""
    key = f"stretch_glove_{name}"
    import sys
    if key in sys.modules:
        return sys.modules[key]
    spec = importlib.util.spec_from_file_location(key, os.path.join(_GLOVE_DIR, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules[key] = module
    spec.loader.exec_module(module)
    return module


_glove_ds = load_glove_module("dataset")
DatasetError = _glove_ds.DatasetError  # one error type across both tool sets
strided = _glove_ds.strided


def _load(directory, name, shape):
    return _glove_ds._load_npy(directory, name, np.float32 if name != "session.npy" else np.int32, shape)


class ArrayDataset:
    def __init__(self, directory):
        self.directory = directory
        if not os.path.isdir(directory):
            raise DatasetError(f"{directory}: not a directory (expected a dataset written by `proprio sim-array`)")
        meta_path = os.path.join(directory, "meta.json")
        if not os.path.exists(meta_path):
            raise DatasetError(f"{meta_path}: missing; meta.json is written last, so the dataset is incomplete "
                               "(the writer was interrupted) or this is not a dataset directory")
        try:
            with open(meta_path, encoding="utf-8") as f:
                self.meta = json.load(f)
        except json.JSONDecodeError as e:
            raise DatasetError(f"{meta_path}:{e.lineno}:{e.colno}: invalid JSON: {e.msg}") from e
        self._check_meta(meta_path)
        c, m = self.cell_count, self.marker_count
        self.cells = _load(directory, "cells.npy", ("N", c))
        n = self.cells.shape[0]
        self.markers = _load(directory, "markers.npy", (n, m, 3))
        self.markers_truth = _load(directory, "markers_truth.npy", (n, m, 3))
        self.pose = _load(directory, "pose.npy", (n,))
        self.session = _load(directory, "session.npy", (n,))
        self._check_arrays()

    # -- checks --------------------------------------------------------------
    def _check_meta(self, where):
        m = self.meta
        if not isinstance(m, dict):
            raise DatasetError(f"{where}: expected a JSON object")
        if m.get("format") != FORMAT:
            raise DatasetError(f"{where}: format {m.get('format')!r}, expected '{FORMAT}'")
        if m.get("version") != VERSION:
            raise DatasetError(f"{where}: version {m.get('version')!r}; this tool reads version {VERSION}")
        for key in ("cell_count", "marker_count", "sessions"):
            if key not in m:
                raise DatasetError(f"{where}: missing key '{key}'")
        for key in ("cell_count", "marker_count"):
            if not isinstance(m[key], int) or m[key] <= 0:
                raise DatasetError(f"{where}: {key} {m[key]!r}, expected a positive integer")
        for key, count in (("cell_names", "cell_count"), ("marker_names", "marker_count")):
            if key in m and len(m[key]) != m[count]:
                raise DatasetError(f"{where}: {key} has {len(m[key])} entries, {count} is {m[count]}")
        sessions = m["sessions"]
        if not isinstance(sessions, list) or not sessions:
            raise DatasetError(f"{where}: no sessions")
        for i, s in enumerate(sessions):
            if s.get("split") not in SPLITS:
                raise DatasetError(f"{where}: sessions[{i}].split {s.get('split')!r}, expected one of {SPLITS}")
            if "frames" not in s:
                raise DatasetError(f"{where}: sessions[{i}] has no 'frames'")

    def _check_arrays(self):
        d = self.directory
        n = self.cells.shape[0]
        if n == 0:
            raise DatasetError(f"{d}: no frames")
        for name, a in (("cells", self.cells), ("markers", self.markers), ("markers_truth", self.markers_truth),
                        ("pose", self.pose)):
            bad = ~np.isfinite(a.reshape(n, -1)).all(axis=1)
            if bad.any():
                raise DatasetError(f"{d}/{name}.npy: {int(bad.sum())} frames hold NaN or infinity "
                                   f"(first: frame {int(np.argmax(bad))}); the writer must drop such frames")
        s = len(self.sessions)
        if self.session.min() < 0 or self.session.max() >= s:
            raise DatasetError(f"{d}/session.npy: values must index meta.json's {s} sessions")
        if np.any(np.diff(self.session) < 0):
            raise DatasetError(f"{d}/session.npy: frames are not in session order")
        first = 0
        for i, sess in enumerate(self.sessions):
            count = int(np.count_nonzero(self.session == i))
            if sess["frames"] != count:
                raise DatasetError(f"{d}/meta.json: session {i} ({sess.get('name', '?')}) says {sess['frames']} "
                                   f"frames, session.npy has {count}")
            if "first_frame" in sess and count and sess["first_frame"] != first:
                raise DatasetError(f"{d}/meta.json: session {i} first_frame {sess['first_frame']}, expected {first}")
            first += count

    # -- properties ------------------------------------------------------------
    @property
    def cell_count(self):
        return self.meta["cell_count"]

    @property
    def marker_count(self):
        return self.meta["marker_count"]

    @property
    def sessions(self):
        return self.meta["sessions"]

    @property
    def layout_name(self):
        return self.meta.get("layout", "")

    @property
    def pose_name(self):
        return self.meta.get("pose_name", "pose")

    @property
    def motion(self):
        """The dataset's motion when all sessions share one (Table 4.1's row label), else 'mixed'."""
        motions = sorted(set(s.get("motion", "?") for s in self.sessions))
        return motions[0] if len(motions) == 1 else "mixed"

    def frames(self, sessions):
        return np.nonzero(np.isin(self.session, np.asarray(list(sessions), dtype=np.int32)))[0]

    def targets(self, frames, truth=False):
        """[n, 3M] marker-major (x0 y0 z0 x1 ...), metres: the network's output layout."""
        src = self.markers_truth if truth else self.markers
        return src[frames].reshape(len(frames), -1)

    def summary(self, sessions):
        return [{"index": int(i), "name": self.sessions[i].get("name"), "motion": self.sessions[i].get("motion"),
                 "donning": self.sessions[i].get("donning"), "split": self.sessions[i].get("split"),
                 "frames": int(self.sessions[i]["frames"])} for i in sessions]


# -- session selectors ---------------------------------------------------------

SELECTOR_HELP = ("comma-separated alternatives, each a session index or key=value terms joined by '&' "
                 "(keys: split, donning, motion, name), e.g. 'split=train&donning=0' or '0,2'")


def select_sessions(data, selector):
    """Session indices matching a selector (see SELECTOR_HELP), in index order."""
    text = (selector or "").strip()
    if not text:
        raise ValueError(f"empty session selector: expected {SELECTOR_HELP}")
    chosen = set()
    for alt in text.split(","):
        alt = alt.strip()
        if re.fullmatch(r"\d+", alt):
            i = int(alt)
            if i >= len(data.sessions):
                raise ValueError(f"session selector '{selector}': index {i}, the dataset has {len(data.sessions)}")
            chosen.add(i)
            continue
        terms = []
        for term in alt.split("&"):
            key, sep, value = term.partition("=")
            key, value = key.strip(), value.strip()
            if not sep or key not in ("split", "donning", "motion", "name"):
                raise ValueError(f"session selector '{selector}': bad term '{term}': expected {SELECTOR_HELP}")
            terms.append((key, value))
        for i, s in enumerate(data.sessions):
            if all(str(s.get(k)) == v for k, v in terms):
                chosen.add(i)
    return sorted(chosen)


# -- pose filters (Table 4.2) --------------------------------------------------

_CMP = {"<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal}


def pose_filter(expression, pose_name="alpha"):
    """Parses 'alpha<20 or alpha>40' (comparisons of the pose value with numbers, joined by
    'or'/'and', 'and' binding tighter; the variable may be written as the dataset's pose_name,
    'alpha' or 'pose') into a function pose[n] -> bool[n]. No eval()."""
    names = {"alpha", "pose", pose_name}
    alternatives = []
    for alt in re.split(r"\s+or\s+", expression.strip()):
        conj = []
        for term in re.split(r"\s+and\s+", alt.strip()):
            mt = re.fullmatch(r"\s*([A-Za-z_][A-Za-z_0-9]*)\s*(<=|>=|<|>)\s*([-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)\s*",
                              term)
            if not mt or mt.group(1) not in names:
                raise ValueError(f"--pose-keep '{expression}': cannot read '{term}'; expected comparisons like "
                                 f"'{pose_name}<20 or {pose_name}>40'")
            conj.append((_CMP[mt.group(2)], float(mt.group(3))))
        alternatives.append(conj)

    def keep(pose):
        pose = np.asarray(pose)
        out = np.zeros(pose.shape, dtype=bool)
        for conj in alternatives:
            part = np.ones(pose.shape, dtype=bool)
            for op, v in conj:
                part &= op(pose, v)
            out |= part
        return out

    return keep


def validation_split(data, frames, fraction):
    """The stretch glove's split: each session's last `fraction` of frames validate (contiguous, so
    near-duplicate neighbouring frames do not leak)."""
    return _glove_ds.validation_split(data, frames, fraction)


# -- errors --------------------------------------------------------------------

def marker_errors_m(pred, target, marker_count):
    """Euclidean error per frame and marker, [n, M], in the units of the inputs."""
    p = np.asarray(pred, dtype=np.float64).reshape(-1, marker_count, 3)
    t = np.asarray(target, dtype=np.float64).reshape(-1, marker_count, 3)
    return np.sqrt(((p - t) ** 2).sum(axis=2))


def error_stats_mm(errors_m):
    """Table 4.1's statistics over all (frame, marker) pairs, millimetres, plus per-marker means."""
    e = np.asarray(errors_m, dtype=np.float64) * 1000.0
    if e.size == 0:
        nan = math.nan
        return {"mean": nan, "std": nan, "max": nan, "median": nan, "frames": 0, "per_marker_mean": []}
    return {"mean": float(e.mean()), "std": float(e.std()), "max": float(e.max()),
            "median": float(np.median(e)), "frames": int(e.shape[0]),
            "per_marker_mean": [float(v) for v in e.mean(axis=0)]}
