#!/usr/bin/python3
"""Dataset loading, normalisation (the C++ formula), grids and splits."""

import json
import os
import shutil
import struct
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

import dataset as ds  # noqa: E402
import synthetic  # noqa: E402


def f32(v):
    return struct.unpack("<f", struct.pack("<f", v))[0]


def reference_normalise(c, lo, hi):
    """The C++ expression evaluated step by step in single precision."""
    x = f32(f32(f32(2.0 * f32(f32(c) - f32(lo))) / f32(f32(hi) - f32(lo))) - 1.0)
    return min(max(x, -2.0), 2.0)


class NormaliseTest(unittest.TestCase):
    def test_end_points_and_clamp(self):
        lo = np.array([10.0, 20.0], np.float32)
        hi = np.array([12.0, 30.0], np.float32)
        cells = np.array([[10.0, 30.0], [11.0, 25.0], [100.0, -100.0]], np.float32)
        x = ds.normalise(cells, lo, hi)
        np.testing.assert_array_equal(x, np.array([[-1, 1], [0, 0], [2, -2]], np.float32))

    def test_bitwise_equal_to_single_precision_formula(self):
        rng = np.random.default_rng(5)
        lo = rng.uniform(5, 30, size=44).astype(np.float32)
        hi = (lo + rng.uniform(0.5, 10, size=44)).astype(np.float32)
        cells = rng.uniform(0, 45, size=(50, 44)).astype(np.float32)
        x = ds.normalise(cells, lo, hi)
        for n in range(50):
            for i in range(44):
                self.assertEqual(float(x[n, i]), reference_normalise(float(cells[n, i]), float(lo[i]), float(hi[i])))

    def test_nan_cell_reads_zero(self):
        x = ds.normalise(np.array([[np.nan, 1.0]], np.float32), np.zeros(2, np.float32), np.ones(2, np.float32))
        self.assertEqual(float(x[0, 0]), 0.0)
        self.assertEqual(float(x[0, 1]), 1.0)

    def test_degenerate_calibration_is_refused(self):
        with self.assertRaises(ValueError):
            ds.normalise(np.ones((1, 2), np.float32), np.ones(2, np.float32), np.ones(2, np.float32))


class GridTest(unittest.TestCase):
    def test_cells_land_on_their_slots(self):
        index = [7, 0, 49, 25]
        values = np.array([[1.0, 2.0, 3.0, 4.0]], np.float32)
        grid = ds.to_input_grid(values, index)
        self.assertEqual(grid.shape, (1, 2, 5, 5))
        self.assertEqual(grid[0, 0, 1, 2], 1.0)  # 7 = layer 0, row 1, col 2
        self.assertEqual(grid[0, 0, 0, 0], 2.0)
        self.assertEqual(grid[0, 1, 4, 4], 3.0)
        self.assertEqual(grid[0, 1, 0, 0], 4.0)
        self.assertEqual(np.count_nonzero(grid), 4)

    def test_output_grid_round_trip(self):
        names = ["a", "b", "c"]
        grid = ["c", None, "a"] + [None] * 22
        angles = np.array([[0.1, 0.2, 0.3]], np.float32)
        y, mask = ds.to_output_grid(angles, grid, names)
        self.assertEqual(y.shape, (1, 1, 5, 5))
        np.testing.assert_array_equal(mask[:3], [True, False, True])
        self.assertEqual(mask.sum(), 2)
        back = ds.from_output_grid(y, grid)
        self.assertAlmostEqual(float(back["c"][0]), 0.3, places=6)
        self.assertAlmostEqual(float(back["a"][0]), 0.1, places=6)


class DatasetTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="stretch_ds_")
        cls.dir = synthetic.generate(os.path.join(cls.tmp, "d"), subjects=2, sessions=2, minutes=0.05,
                                     exploration_seconds=2.0, seed=3)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp)

    def copy(self):
        target = tempfile.mkdtemp(prefix="stretch_ds_copy_", dir=self.tmp)
        shutil.rmtree(target)
        shutil.copytree(self.dir, target)
        return target

    def test_loads_and_selects(self):
        d = ds.Dataset(self.dir)
        self.assertEqual(d.subjects(), [0, 1])
        self.assertEqual(d.sessions_of(1), [2, 3])
        frames = d.frames([2], phase=1)
        self.assertTrue(np.all(d.session[frames] == 2))
        self.assertTrue(np.all(d.phase[frames] == 1))
        x = d.inputs(frames)
        self.assertEqual(x.shape, (len(frames), 2, 5, 5))
        # the session's own calibration maps its exploration phase to about [-1, 1] (median-filtered
        # extremes, so single noisy frames may lie outside)
        explored = d.normalised(d.frames([2], phase=0))
        self.assertGreater(np.mean(np.abs(explored) <= 1.1), 0.9)
        self.assertLess(explored.min(), -0.8)
        self.assertGreater(explored.max(), 0.8)

    def test_missing_file_is_named(self):
        broken = self.copy()
        os.remove(os.path.join(broken, "angles.npy"))
        with self.assertRaisesRegex(ds.DatasetError, "angles.npy: missing"):
            ds.Dataset(broken)

    def test_wrong_shape_is_named(self):
        broken = self.copy()
        np.save(os.path.join(broken, "calib_min.npy"), np.zeros((4, 43), np.float32))
        with self.assertRaisesRegex(ds.DatasetError, r"calib_min.npy: shape \(4, 43\)"):
            ds.Dataset(broken)

    def test_bad_meta_names_the_line(self):
        broken = self.copy()
        with open(os.path.join(broken, "meta.json"), "w") as f:
            f.write('{\n "cell_count": 44,\n "layout": \n}\n')
        with self.assertRaisesRegex(ds.DatasetError, r"meta.json:4:1"):
            ds.Dataset(broken)

    def test_unknown_dof_in_output_grid(self):
        broken = self.copy()
        path = os.path.join(broken, "meta.json")
        with open(path) as f:
            meta = json.load(f)
        meta["output_grid"][0] = "thumb_wiggle"
        with open(path, "w") as f:
            json.dump(meta, f)
        with self.assertRaisesRegex(ds.DatasetError, r"output_grid\[0\] = 'thumb_wiggle'"):
            ds.Dataset(broken)

    def test_validation_split_takes_each_sessions_tail(self):
        d = ds.Dataset(self.dir)
        frames = d.frames([0, 1, 3])
        train, val = ds.validation_split(d, frames, 0.2)
        self.assertEqual(len(train) + len(val), len(frames))
        for s in (0, 1, 3):
            tr = train[d.session[train] == s]
            va = val[d.session[val] == s]
            self.assertGreater(len(va), 0)
            self.assertLess(tr.max(), va.min())  # validation strictly after training, per session
            self.assertAlmostEqual(len(va) / (len(va) + len(tr)), 0.2, delta=0.01)


if __name__ == "__main__":
    unittest.main()
