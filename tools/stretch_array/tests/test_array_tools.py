#!/usr/bin/python3
"""Stretch-array regressors on a small synthetic dataset: loading and refusal of broken
datasets, selectors and pose filters, exact folding for export, tiny training of dnn/lr/svm
with ONNX outlines, DNN vs LR on a nonlinear map, and evaluate.py's numbers against a direct
numpy computation. Seconds, not minutes."""

import contextlib
import io
import json
import os
import shutil
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
import torch  # noqa: E402

import array_dataset as ads  # noqa: E402
import evaluate  # noqa: E402
import regressors  # noqa: E402
import synthetic  # noqa: E402
import train  # noqa: E402

onnx_info = ads.load_glove_module("onnx_info")

# Ops each export may use. All were loaded and run by OpenCV 4.6 DNN (readNetFromONNX) against the
# PyTorch outputs (agreement <= 3e-6 m) when this was written; a new op needs that check again.
ALLOWED_OPS = {"dnn": {"Gemm", "Relu"}, "lr": {"Gemm"}, "svm": {"Gemm", "MatMul", "Mul", "Add", "Exp"}}


def load_json(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def read_text(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def save_json(value, path):
    with open(path, "w", encoding="utf-8") as f:
        json.dump(value, f)


def run(main, args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(args)
    return code, out.getvalue(), err.getvalue()


class DatasetTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="stretch_array_ds_")
        cls.good = synthetic.generate(os.path.join(cls.tmp, "good"), cells=8, markers=3,
                                      sessions=(("train", 0, 60), ("test", 0, 20), ("test", 1, 20)), seed=3)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp)

    def broken_copy(self, name):
        d = os.path.join(self.tmp, name)
        shutil.copytree(self.good, d)
        return d

    def assertRefused(self, directory, *fragments):
        with self.assertRaises(ads.DatasetError) as ctx:
            ads.ArrayDataset(directory)
        for f in fragments:
            self.assertIn(f, str(ctx.exception))

    def test_loads_the_synthetic_dataset(self):
        data = ads.ArrayDataset(self.good)
        self.assertEqual(data.cells.shape, (100, 8))
        self.assertEqual(data.targets(np.arange(5)).shape, (5, 9))
        # marker-major: row k holds x, y, z of marker 0, then marker 1 ...
        np.testing.assert_array_equal(data.targets(np.array([7]))[0, 3:6], data.markers[7, 1])
        self.assertEqual(data.motion, "wrist")

    def test_refuses_missing_meta(self):
        d = self.broken_copy("no_meta")
        os.remove(os.path.join(d, "meta.json"))
        self.assertRefused(d, "meta.json", "incomplete")

    def test_refuses_mismatched_shapes(self):
        d = self.broken_copy("bad_shape")
        np.save(os.path.join(d, "markers.npy"), np.zeros((100, 4, 3), np.float32))
        self.assertRefused(d, "markers.npy", "shape")
        d = self.broken_copy("short_pose")
        np.save(os.path.join(d, "pose.npy"), np.zeros(99, np.float32))
        self.assertRefused(d, "pose.npy", "shape")

    def test_refuses_nan(self):
        d = self.broken_copy("nan")
        cells = np.load(os.path.join(d, "cells.npy"))
        cells[42, 3] = np.nan
        np.save(os.path.join(d, "cells.npy"), cells)
        self.assertRefused(d, "cells.npy", "NaN", "frame 42")

    def test_refuses_wrong_dtype_and_session_counts(self):
        d = self.broken_copy("dtype")
        np.save(os.path.join(d, "session.npy"), np.load(os.path.join(d, "session.npy")).astype(np.int64))
        self.assertRefused(d, "session.npy", "dtype")
        d = self.broken_copy("counts")
        meta = load_json(os.path.join(d, "meta.json"))
        meta["sessions"][0]["frames"] = 61
        save_json(meta, os.path.join(d, "meta.json"))
        self.assertRefused(d, "session 0", "61")

    def test_refuses_other_formats(self):
        d = self.broken_copy("format")
        meta = load_json(os.path.join(d, "meta.json"))
        meta["format"] = "proprio-stretch-glove-dataset"
        save_json(meta, os.path.join(d, "meta.json"))
        self.assertRefused(d, "format")

    def test_train_cli_reports_a_broken_dataset(self):
        d = self.broken_copy("cli")
        os.remove(os.path.join(d, "meta.json"))
        code, _, err = run(train.main, [d, "--model", "lr", "--out", os.path.join(self.tmp, "m")])
        self.assertEqual(code, 2)
        self.assertIn("meta.json", err)

    def test_session_selectors(self):
        data = ads.ArrayDataset(self.good)
        self.assertEqual(ads.select_sessions(data, "split=train"), [0])
        self.assertEqual(ads.select_sessions(data, "split=test"), [1, 2])
        self.assertEqual(ads.select_sessions(data, "split=test&donning=1"), [2])
        self.assertEqual(ads.select_sessions(data, "0,2"), [0, 2])
        for bad in ("", "colour=red", "7"):
            with self.assertRaises(ValueError):
                ads.select_sessions(data, bad)

    def test_pose_filter(self):
        pose = np.linspace(0, 100, 101)
        keep = ads.pose_filter("alpha<20 or alpha>40")(pose)
        np.testing.assert_array_equal(keep, (pose < 20) | (pose > 40))
        keep = ads.pose_filter("pose>=10 and pose<=30 or alpha>90")(pose)
        np.testing.assert_array_equal(keep, ((pose >= 10) & (pose <= 30)) | (pose > 90))
        for bad in ("alpha<<3", "beta<3", "__import__('os')"):
            with self.assertRaises(ValueError):
                ads.pose_filter(bad)
        self.assertEqual(evaluate.keep_expression(20, 30), "alpha<20 or alpha>30")
        self.assertEqual(evaluate.keep_expression(None, 20), "alpha>20")
        self.assertIsNone(evaluate.keep_expression(None, None))
        self.assertEqual(evaluate.parse_rows("60:max,min:20"), [(60.0, None), (None, 20.0)])


class FoldingTest(unittest.TestCase):
    def test_folded_dnn_computes_what_the_trained_one_computes(self):
        torch.manual_seed(0)
        model = regressors.ArrayDNN(10, 6, input_width=12, hidden=(16, 16, 8))
        rng = np.random.default_rng(1)
        x = rng.uniform(0.8, 1.6, (50, 10))
        y = rng.normal(0, 0.05, (50, 6))
        model.set_standardisation(regressors.Standardiser(x), regressors.Standardiser(y))
        for m in model.modules():  # non-trivial BatchNorm statistics and affine parameters
            if isinstance(m, torch.nn.BatchNorm1d):
                m.weight.data.uniform_(0.5, 1.5)
                m.bias.data.uniform_(-0.3, 0.3)
        model.train()
        with torch.no_grad():
            for _ in range(5):
                model(torch.from_numpy(rng.uniform(0.8, 1.6, (32, 10)).astype(np.float32)))
        model.eval()
        folded = regressors.fold_dnn(model)
        probe = regressors.probe_inputs(10)
        with torch.no_grad():
            ref, got = model(probe), folded(probe)
        self.assertGreater(float(ref.std()), 1e-3)  # not trivially constant
        self.assertLess(float((ref - got).abs().max()), 1e-5)

    def test_kernel_ridge_graph_is_the_rbf_expansion(self):
        rng = np.random.default_rng(2)
        x = rng.uniform(0.8, 1.6, (200, 5))
        y = np.stack([np.sin(3 * x[:, 0]), x[:, 1] * x[:, 2], np.cos(x[:, 3])], 1) * 0.01
        model, info = regressors.fit_kernel_ridge(x, y, x[:40], y[:40], marker_count=1, max_centres=50)
        # The same function written directly: standardise, Gaussian of squared distances to the centres.
        s = regressors.Standardiser(x)
        w = model.cross.weight.detach().double().numpy()  # 2 gamma z
        z = w / (2 * info["gamma"])
        k = regressors._rbf(s(x[:30]), z, info["gamma"])
        direct = k @ model.combine.weight.detach().double().numpy().T + model.combine.bias.detach().double().numpy()
        np.testing.assert_allclose(regressors.predict(model, x[:30]), direct, atol=1e-5)
        self.assertLess(info["val_error_mm"], 1.0)


class ToolsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="stretch_array_tools_")
        cls.data = synthetic.generate(os.path.join(cls.tmp, "data"), cells=16, markers=4, seed=5)
        cls.logs = {}
        for kind in regressors.KINDS:
            code, out, err = run(train.main, [cls.data, "--model", kind, "--tiny", "--threads", "1", "--max-centres",
                                              "300", "--quiet", "--out", os.path.join(cls.tmp, kind)])
            assert code == 0, err
            cls.logs[kind] = out

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp)

    def sidecar(self, kind):
        with open(os.path.join(self.tmp, kind, "model.json"), encoding="utf-8") as f:
            return json.load(f)

    def test_each_model_writes_onnx_sidecar_and_weights(self):
        for kind in regressors.KINDS:
            for name in ("model.onnx", "model.json", "model.pt"):
                self.assertTrue(os.path.exists(os.path.join(self.tmp, kind, name)), f"{kind}/{name}")
            s = self.sidecar(kind)
            self.assertEqual((s["cell_count"], s["marker_count"], s["kind"]), (16, 4, kind))
            self.assertEqual(s["train_frames"] + s["val_frames"], 1600)
            self.assertEqual([t["split"] for t in s["trained_on"]], ["train"])
            self.assertTrue(np.isfinite(s["val_error_mm"]), kind)
            self.assertIn("wrote", self.logs[kind])

    def test_onnx_outline_names_shapes_and_ops(self):
        for kind in regressors.KINDS:
            path = os.path.join(self.tmp, kind, "model.onnx")
            info = onnx_info.read(path)
            self.assertEqual(info["inputs"], {"cells": [1, 16]}, kind)
            self.assertEqual(info["outputs"], {"markers": [1, 12]}, kind)
            self.assertEqual(info["opset"], train.OPSET)
            ops = set(info["ops"])
            self.assertTrue(ops <= ALLOWED_OPS[kind], f"{kind} uses {sorted(ops - ALLOWED_OPS[kind])}")
            self.assertEqual(sorted(ops), self.sidecar(kind)["onnx_ops"])
            checker = getattr(torch._C, "_check_onnx_proto", None)
            if checker is not None:  # torch's own ONNX checker (there is no `onnx` module on Debian)
                with open(path, "rb") as f:
                    blob = f.read()
                checker(blob)
                with self.assertRaises(RuntimeError):
                    checker(blob[: len(blob) // 2])

    def test_reloaded_model_predicts_what_the_export_was_checked_against(self):
        for kind in regressors.KINDS:
            model, side = train.load(os.path.join(self.tmp, kind))
            self.assertEqual(side["kind"], kind)
            probe = regressors.probe_inputs(16)
            with torch.no_grad():
                gap = (regressors.inference_form(model)(probe) - model(probe)).abs().max().item()
            self.assertLess(gap, 1e-5, kind)

    def test_dnn_beats_lr_on_the_nonlinear_map(self):
        data = ads.ArrayDataset(self.data)
        same = ads.select_sessions(data, "split=test&donning=0")
        err = {k: train.test_errors(data, train.load(os.path.join(self.tmp, k))[0], same)["truth"]["mean"]
               for k in ("dnn", "lr")}
        self.assertLess(err["dnn"], 0.8 * err["lr"], err)

    def test_evaluate_matches_a_direct_numpy_computation(self):
        out = os.path.join(self.tmp, "eval_lr")
        code, text, err = run(evaluate.main, ["model", os.path.join(self.tmp, "lr"), self.data, "--out", out])
        self.assertEqual(code, 0, err)
        self.assertIn("| all |", text)
        result = load_json(os.path.join(out, "model_eval.json"))
        # LR in plain numpy from the stored weights, errors with np.linalg.norm.
        blob = torch.load(os.path.join(self.tmp, "lr", "model.pt"))
        w = blob["state_dict"]["linear.weight"].double().numpy()
        b = blob["state_dict"]["linear.bias"].double().numpy()
        cells = np.load(os.path.join(self.data, "cells.npy"))
        session = np.load(os.path.join(self.data, "session.npy"))
        truth = np.load(os.path.join(self.data, "markers_truth.npy"))
        labelled = np.load(os.path.join(self.data, "markers.npy"))
        test = np.isin(session, [1, 2])
        pred = (cells[test].astype(np.float64) @ w.T + b).reshape(-1, 4, 3)
        for ref, key in ((truth, "truth"), (labelled, "labelled")):
            e = np.linalg.norm(pred - ref[test], axis=2) * 1000.0
            got = result["all"][key]
            self.assertTrue(all(np.isfinite(got[k]) for k in ("mean", "std", "max")))
            # float32 inference vs float64 here: relative agreement
            np.testing.assert_allclose([got["mean"], got["std"], got["max"]], [e.mean(), e.std(), e.max()],
                                       rtol=1e-5, atol=1e-4)
            np.testing.assert_allclose(got["per_marker_mean"], e.mean(axis=0), rtol=1e-5, atol=1e-4)
        self.assertEqual(result["all"]["frames"], int(test.sum()))

    def test_evaluate_refuses_a_model_for_another_array(self):
        other = synthetic.generate(os.path.join(self.tmp, "other"), cells=10, markers=4,
                                   sessions=(("train", 0, 30), ("test", 0, 10)), seed=9)
        code, _, err = run(evaluate.main, ["model", os.path.join(self.tmp, "lr"), other])
        self.assertEqual(code, 2)
        self.assertIn("cells", err)

    def test_table41_writes_json_and_markdown(self):
        out = os.path.join(self.tmp, "t41")
        code, text, err = run(evaluate.main, ["table41", self.data, "--models", "lr,svm", "--max-centres", "200",
                                              "--quiet", "--out", out])
        self.assertEqual(code, 0, err)
        rows = load_json(os.path.join(out, "table41.json"))["rows"]
        self.assertEqual([r["kind"] for r in rows], ["lr", "svm"])
        for r in rows:  # same-donning test session only
            self.assertEqual(r["test"]["sessions"], [1])
            self.assertTrue(np.isfinite(r["test"]["truth"]["mean"]))
        md = read_text(os.path.join(out, "table41.md"))
        self.assertIn("| wrist | LR |", md)
        self.assertIn("12.80", md)  # the thesis's LR mean for the wrist, for reference

    def test_table42_counts_the_kept_frames(self):
        out = os.path.join(self.tmp, "t42")
        code, _, err = run(evaluate.main, ["table42", self.data, "--model", "lr", "--rows", "min:max,60:max,20:40",
                                           "--quiet", "--out", out])
        self.assertEqual(code, 0, err)
        rows = load_json(os.path.join(out, "table42.json"))["rows"]
        pose = np.load(os.path.join(self.data, "pose.npy"))[np.load(os.path.join(self.data, "session.npy")) == 0]
        self.assertEqual([r["frames"] for r in rows],
                         [len(pose), int((pose < 60).sum()), int(((pose < 20) | (pose > 40)).sum())])
        for r in rows:
            self.assertTrue(np.isfinite(r["test"]["truth"]["max"]))
        # Extrapolation (nothing above 60 degrees seen) is worse than training on everything.
        self.assertGreater(rows[1]["test"]["truth"]["mean"], rows[0]["test"]["truth"]["mean"])

    def test_redonning_separates_the_sessions(self):
        out = os.path.join(self.tmp, "rd")
        code, _, err = run(evaluate.main, ["redonning", self.data, "--model", "lr", "--quiet", "--out", out])
        self.assertEqual(code, 0, err)
        r = load_json(os.path.join(out, "redonning.json"))
        self.assertEqual(r["same_donning"]["sessions"], [1])
        self.assertEqual(r["redonned"]["sessions"], [2])
        # The synthetic re-donning changes every cell's gain by ~3 %: the error grows.
        self.assertGreater(r["redonned"]["truth"]["mean"], r["same_donning"]["truth"]["mean"])

    def test_pose_keep_reduces_training_frames(self):
        out = os.path.join(self.tmp, "kept")
        code, _, err = run(train.main, [self.data, "--model", "lr", "--pose-keep", "alpha<20 or alpha>40", "--quiet",
                                        "--out", out])
        self.assertEqual(code, 0, err)
        s = load_json(os.path.join(out, "model.json"))
        pose = np.load(os.path.join(self.data, "pose.npy"))[:1600]
        self.assertEqual(s["train_frames"] + s["val_frames"], int(((pose < 20) | (pose > 40)).sum()))
        code, _, err = run(train.main, [self.data, "--model", "lr", "--pose-keep", "alpha<-5", "--quiet", "--out", out])
        self.assertEqual(code, 2)
        self.assertIn("too few", err)


if __name__ == "__main__":
    unittest.main()
