#!/usr/bin/python3
"""Stretch-glove training datasets: loading, normalisation, grids and splits.

A dataset is a directory written by `proprio sim-glove --out DIR` (or by
synthetic.py for tests) holding:
  meta.json      layout, cell_count, frame_rate_hz, output_grid (25: HandDof name
                 or null, row-major 5x5), input_grid_index (cell_count ints: flat
                 index layer*25 + row*5 + col into the 2x5x5 input), dof_names,
                 sessions [{subject, session, donning, frames, hand_length_m,
                 hand_width_m}], units, generator
  cells.npy      float32 [N, cells]  recovered cell capacitances, pF
  angles.npy     float32 [N, dofs]   ground-truth joint angles, radians, dof_names order
  session.npy    int32   [N]         index into meta["sessions"]
  subject.npy    int32   [N]
  phase.npy      uint8   [N]         0 = calibration exploration, 1 = task motion
  calib_min.npy, calib_max.npy  float32 [S, cells]  each session's min-max calibration

Normalisation is the C++ MinMaxCalibration's, exactly:
  x = 2 (c - min) / (max - min) - 1, clamped to [-2, 2].
"""

import json
import math
import os

import numpy as np

GRID = 5
INPUT_SLOTS = 2 * GRID * GRID
OUTPUT_SLOTS = GRID * GRID
CLAMP = 2.0

CALIBRATION_MODES = ("session", "global")


class DatasetError(Exception):
    """A dataset file is missing or does not follow the format; the message says which and what was expected."""


def _load_npy(directory, name, dtype, shape):
    path = os.path.join(directory, name)
    if not os.path.exists(path):
        raise DatasetError(f"{path}: missing (a dataset directory needs {name}, {dtype.__name__} {shape})")
    try:
        array = np.load(path, allow_pickle=False)
    except Exception as e:  # numpy raises several types for bad headers/truncation
        raise DatasetError(f"{path}: not a readable .npy file ({e})") from e
    if array.dtype != dtype:
        raise DatasetError(f"{path}: dtype {array.dtype}, expected {np.dtype(dtype)}")
    if array.ndim != len(shape):
        raise DatasetError(f"{path}: shape {array.shape}, expected {len(shape)} dimensions {shape}")
    for axis, want in enumerate(shape):
        if isinstance(want, int) and array.shape[axis] != want:
            raise DatasetError(f"{path}: shape {array.shape}, expected {shape}")
    return array


def normalise(cells, cal_min, cal_max):
    """The C++ MinMaxCalibration::normalize, vectorised. cells [N, C]; min/max [C] or [N, C]."""
    cells = np.asarray(cells, dtype=np.float32)
    lo = np.asarray(cal_min, dtype=np.float32)
    span = np.asarray(cal_max, dtype=np.float32) - lo
    if np.any(span <= 0):
        raise ValueError("calibration max must exceed min for every cell")
    # Same operations in the same order as the C++ (single precision), so both give the same bits.
    x = np.float32(2.0) * (cells - lo) / span - np.float32(1.0)
    x = np.clip(x, np.float32(-CLAMP), np.float32(CLAMP)).astype(np.float32)
    return np.where(np.isnan(cells), np.float32(0.0), x)  # the C++ maps a NaN cell to 0


class Dataset:
    def __init__(self, directory):
        self.directory = directory
        meta_path = os.path.join(directory, "meta.json")
        if not os.path.isdir(directory):
            raise DatasetError(f"{directory}: not a directory (expected a dataset written by `proprio sim-glove --out DIR`)")
        if not os.path.exists(meta_path):
            raise DatasetError(f"{meta_path}: missing (every dataset directory has a meta.json)")
        try:
            with open(meta_path, encoding="utf-8") as f:
                self.meta = json.load(f)
        except json.JSONDecodeError as e:
            raise DatasetError(f"{meta_path}:{e.lineno}:{e.colno}: invalid JSON: {e.msg}") from e
        self._check_meta(meta_path)
        c = self.cell_count
        d = len(self.dof_names)
        s = len(self.sessions)
        self.cells = _load_npy(directory, "cells.npy", np.float32, ("N", c))
        n = self.cells.shape[0]
        self.angles = _load_npy(directory, "angles.npy", np.float32, (n, d))
        self.session = _load_npy(directory, "session.npy", np.int32, (n,))
        self.subject = _load_npy(directory, "subject.npy", np.int32, (n,))
        self.phase = _load_npy(directory, "phase.npy", np.uint8, (n,))
        self.calib_min = _load_npy(directory, "calib_min.npy", np.float32, (s, c))
        self.calib_max = _load_npy(directory, "calib_max.npy", np.float32, (s, c))
        self._check_arrays()

    # -- meta ---------------------------------------------------------------
    def _check_meta(self, where):
        m = self.meta
        for key in ("cell_count", "output_grid", "input_grid_index", "dof_names", "sessions"):
            if key not in m:
                raise DatasetError(f"{where}: missing key '{key}'")
        c = m["cell_count"]
        if not isinstance(c, int) or c <= 0 or c > INPUT_SLOTS:
            raise DatasetError(f"{where}: cell_count {c!r}, expected an integer 1..{INPUT_SLOTS}")
        gi = m["input_grid_index"]
        if len(gi) != c or any((not isinstance(i, int)) or i < 0 or i >= INPUT_SLOTS for i in gi):
            raise DatasetError(f"{where}: input_grid_index must hold {c} integers in 0..{INPUT_SLOTS - 1}")
        if len(set(gi)) != len(gi):
            raise DatasetError(f"{where}: input_grid_index puts two cells in one slot")
        og = m["output_grid"]
        if len(og) != OUTPUT_SLOTS:
            raise DatasetError(f"{where}: output_grid has {len(og)} entries, expected {OUTPUT_SLOTS} (row-major 5x5)")
        names = m["dof_names"]
        for k, name in enumerate(og):
            if name is not None and name not in names:
                raise DatasetError(f"{where}: output_grid[{k}] = '{name}' is not one of dof_names")
        used = [n for n in og if n is not None]
        if len(set(used)) != len(used):
            raise DatasetError(f"{where}: output_grid names a DoF twice")
        if not m["sessions"]:
            raise DatasetError(f"{where}: no sessions")

    @property
    def cell_count(self):
        return self.meta["cell_count"]

    @property
    def dof_names(self):
        return list(self.meta["dof_names"])

    @property
    def sessions(self):
        return self.meta["sessions"]

    @property
    def input_grid_index(self):
        return np.asarray(self.meta["input_grid_index"], dtype=np.int64)

    @property
    def output_grid(self):
        return list(self.meta["output_grid"])

    @property
    def layout_name(self):
        return self.meta.get("layout", "")

    @property
    def frame_rate_hz(self):
        return float(self.meta.get("frame_rate_hz", 60.0))

    def _check_arrays(self):
        n = self.cells.shape[0]
        s = len(self.sessions)
        if n == 0:
            raise DatasetError(f"{self.directory}: no frames")
        if self.session.min() < 0 or self.session.max() >= s:
            raise DatasetError(f"{self.directory}/session.npy: values must index meta.json's {s} sessions")
        if not np.all(np.isfinite(self.angles)):
            raise DatasetError(f"{self.directory}/angles.npy: contains NaN or infinity")
        if np.any(self.phase > 1):
            raise DatasetError(f"{self.directory}/phase.npy: values must be 0 (exploration) or 1 (task)")
        bad = np.nonzero(np.any(self.calib_max <= self.calib_min, axis=1))[0]
        if len(bad):
            raise DatasetError(f"{self.directory}/calib_max.npy: max <= min for some cell in sessions {bad.tolist()}")
        for i, sess in enumerate(self.sessions):
            count = int(np.count_nonzero(self.session == i))
            frames = sess.get("frames")
            if frames is not None and frames != count:
                raise DatasetError(
                    f"{self.directory}/meta.json: session {i} says {frames} frames, session.npy has {count}")

    # -- selection ----------------------------------------------------------
    def subjects(self):
        return sorted(set(int(s) for s in np.unique(self.subject)))

    def sessions_of(self, subject):
        """Session indices (into meta sessions) of one subject, in index order."""
        return sorted(set(int(s) for s in np.unique(self.session[self.subject == subject])))

    def frames(self, sessions, phase=None):
        """Frame indices of these sessions (in time order), optionally one phase only."""
        mask = np.isin(self.session, np.asarray(list(sessions), dtype=np.int32))
        if phase is not None:
            mask &= self.phase == phase
        return np.nonzero(mask)[0]

    def donning(self, session_index):
        return self.sessions[session_index].get("donning", session_index)

    # -- tensors ------------------------------------------------------------
    def global_calibration(self, frames):
        """Scenario 3: per-cell min and max over these (training) frames."""
        lo = self.cells[frames].min(axis=0)
        hi = self.cells[frames].max(axis=0)
        hi = np.where(hi > lo, hi, lo + np.float32(1e-3))
        return lo.astype(np.float32), hi.astype(np.float32)

    def normalised(self, frames, calibration="session", global_min=None, global_max=None):
        if calibration == "session":
            s = self.session[frames]
            return normalise(self.cells[frames], self.calib_min[s], self.calib_max[s])
        if calibration == "global":
            return normalise(self.cells[frames], global_min, global_max)
        raise ValueError(f"unknown calibration '{calibration}': expected one of {CALIBRATION_MODES}")

    def inputs(self, frames, calibration="session", global_min=None, global_max=None, cell_mask=None):
        """[n, 2, 5, 5] network inputs. cell_mask: bool [cells]; False cells read 0 (ablation)."""
        x = self.normalised(frames, calibration, global_min, global_max)
        if cell_mask is not None:
            x = x * np.asarray(cell_mask, dtype=np.float32)[None, :]
        return to_input_grid(x, self.input_grid_index)

    def targets(self, frames):
        """[n, 1, 5, 5] angle grids (empty cells 0) and the [25] bool mask of cells that hold a DoF."""
        return to_output_grid(self.angles[frames], self.output_grid, self.dof_names)


def to_input_grid(normalised_cells, input_grid_index):
    n = normalised_cells.shape[0]
    grid = np.zeros((n, INPUT_SLOTS), dtype=np.float32)
    grid[:, np.asarray(input_grid_index)] = normalised_cells
    return grid.reshape(n, 2, GRID, GRID)


def output_mask(output_grid):
    return np.array([name is not None for name in output_grid], dtype=bool)


def to_output_grid(angles, output_grid, dof_names):
    n = angles.shape[0]
    grid = np.zeros((n, OUTPUT_SLOTS), dtype=np.float32)
    for k, name in enumerate(output_grid):
        if name is not None:
            grid[:, k] = angles[:, dof_names.index(name)]
    return grid.reshape(n, 1, GRID, GRID), output_mask(output_grid)


def from_output_grid(pose, output_grid):
    """[n, 1, 5, 5] -> {dof name: [n]} for the cells that hold a DoF."""
    flat = np.asarray(pose).reshape(-1, OUTPUT_SLOTS)
    return {name: flat[:, k] for k, name in enumerate(output_grid) if name is not None}


def validation_split(dataset, frames, fraction):
    """Splits frames into (train, validation): the last `fraction` of each
    session's frames validate. Contiguous tails, because neighbouring frames
    at 60 Hz are nearly identical and a random split would leak."""
    frames = np.asarray(frames)
    if fraction <= 0:
        return frames, frames[:0]
    train, val = [], []
    for s in np.unique(dataset.session[frames]):
        f = frames[dataset.session[frames] == s]
        cut = len(f) - max(1, int(round(fraction * len(f))))
        train.append(f[:cut])
        val.append(f[cut:])
    return np.concatenate(train), np.concatenate(val)


def strided(frames, max_frames):
    """Every k-th frame so that at most max_frames remain (0: all). Neighbouring
    frames at 60 Hz are near duplicates, so this loses little but time."""
    if max_frames <= 0 or len(frames) <= max_frames:
        return frames
    return frames[:: int(math.ceil(len(frames) / max_frames))]


def summary(dataset, frames):
    sessions = sorted(set(int(s) for s in np.unique(dataset.session[frames])))
    return {
        "directory": dataset.directory,
        "layout": dataset.layout_name,
        "generator": dataset.meta.get("generator"),
        "frames": int(len(frames)),
        "sessions": [
            {"index": s, "subject": dataset.sessions[s].get("subject"), "session": dataset.sessions[s].get("session"),
             "donning": dataset.sessions[s].get("donning"),
             "frames": int(np.count_nonzero(dataset.session[frames] == s))}
            for s in sessions
        ],
        "subjects": sorted(set(int(s) for s in np.unique(dataset.subject[frames]))),
    }
