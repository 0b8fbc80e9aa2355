#!/usr/bin/python3
"""Tiny runs of the command-line tools on a small synthetic dataset: train.py
(files, ONNX outline, determinism, that it learns), finetune.py, evaluate.py
and the error paths. Seconds, not minutes."""

import contextlib
import io
import json
import os
import shutil
import sys
import tempfile
import unittest
import zlib

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

import dataset as ds  # noqa: E402
import evaluate  # noqa: E402
import finetune  # noqa: E402
import onnx_info  # noqa: E402
import synthetic  # noqa: E402
import train  # noqa: E402
import training  # noqa: E402

# What OpenCV 4.6's ONNX importer handles for these networks (checked by the C++ agreement test);
# a new op appearing in the export needs that test run before it is added here.
OPENCV_SAFE_OPS = {"Conv", "Relu", "Concat", "Constant", "Reshape", "MatMul", "Tanh", "Mul", "Add", "Flatten", "Gemm"}


def run(main, args):
    """Runs a tool's main(), returning (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(args)
    return code, out.getvalue(), err.getvalue()


class ToolsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="stretch_tools_")
        cls.data = synthetic.generate(os.path.join(cls.tmp, "data"), subjects=3, sessions=2, minutes=0.25,
                                      exploration_seconds=5.0, seed=11)
        cls.unet = os.path.join(cls.tmp, "unet.onnx")
        code, cls.unet_log, err = run(train.main, ["--data", cls.data, "--model", "unet", "--epochs", "4",
                                                   "--unet-width", "8", "--exclude-subject", "2", "--threads", "1",
                                                   "--batch", "64", "--lr", "1e-3",
                                                   "--seed", "5", "--out", cls.unet])
        assert code == 0, err

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp)

    def test_train_writes_model_sidecar_and_weights(self):
        for ext in (".onnx", ".json", ".pt"):
            self.assertTrue(os.path.exists(self.unet[:-5] + ext), ext)
        with open(self.unet[:-5] + ".json") as f:
            sidecar = json.load(f)
        data = ds.Dataset(self.data)
        self.assertEqual(sidecar["format"], "proprio-stretch-pose-model")
        self.assertEqual(sidecar["input_grid_index"], [int(i) for i in data.input_grid_index])
        self.assertEqual(sidecar["output_grid"], data.output_grid)
        self.assertEqual(sidecar["model"]["kind"], "unet")
        self.assertEqual(sidecar["seed"], 5)
        self.assertEqual(sidecar["training"]["data"]["subjects"], [0, 1])  # subject 2 left out
        self.assertGreater(sidecar["validation"]["mean_deg"], 0.0)
        with open(self.unet, "rb") as f:
            self.assertEqual(sidecar["onnx_crc32"], zlib.crc32(f.read()))
        self.assertIn("epoch 4/4", self.unet_log)  # progress per epoch

    def test_onnx_outline(self):
        info = onnx_info.read(self.unet)
        self.assertEqual(info["opset"], training.DEFAULT_OPSET)
        self.assertEqual(info["inputs"], {"stretch": [1, 2, 5, 5]})
        self.assertEqual(info["outputs"], {"pose": [1, 1, 5, 5]})
        self.assertTrue(set(info["ops"]) <= OPENCV_SAFE_OPS, set(info["ops"]) - OPENCV_SAFE_OPS)
        self.assertNotIn("BatchNormalization", info["ops"])
        self.assertNotIn("ConvTranspose", info["ops"])

    def test_fcn_and_opset_13(self):
        path = os.path.join(self.tmp, "fcn13.onnx")
        code, _, err = run(train.main, ["--data", self.data, "--model", "fcn", "--fcn-hidden", "32,16",
                                        "--epochs", "1", "--opset", "13", "--threads", "1", "--quiet", "--out", path])
        self.assertEqual(code, 0, err)
        info = onnx_info.read(path)
        self.assertEqual(info["opset"], 13)
        self.assertEqual(info["inputs"], {"stretch": [1, 2, 5, 5]})
        self.assertEqual(info["outputs"], {"pose": [1, 1, 5, 5]})
        self.assertTrue(set(info["ops"]) <= OPENCV_SAFE_OPS, set(info["ops"]) - OPENCV_SAFE_OPS)

    def test_same_seed_same_bytes_other_seed_other_bytes(self):
        paths = [os.path.join(self.tmp, f"det{i}.onnx") for i in range(3)]
        for path, seed in zip(paths, (3, 3, 4)):
            code, _, err = run(train.main, ["--data", self.data, "--model", "unet", "--unet-width", "4",
                                            "--epochs", "1", "--threads", "1", "--quiet", "--seed", str(seed),
                                            "--out", path])
            self.assertEqual(code, 0, err)
        blobs = []
        for p in paths:
            with open(p, "rb") as f:
                blobs.append(f.read())
        self.assertEqual(blobs[0], blobs[1])
        self.assertNotEqual(blobs[0], blobs[2])

    def test_it_learns(self):
        """Beats predicting each DoF's training mean on the held-out tail of the training sessions."""
        data = ds.Dataset(self.data)
        model, sidecar = training.load_checkpoint(self.unet[:-5] + ".pt")
        train_f, val_f = ds.validation_split(data, data.frames(data.sessions_of(0) + data.sessions_of(1)), 0.1)
        y, _ = data.targets(val_f)
        errors = training.angle_errors_deg(training.predict(model, data.inputs(val_f)), y, data.output_grid)
        self.assertAlmostEqual(errors["mean_deg"], sidecar["validation"]["mean_deg"], places=4)
        train_y, _ = data.targets(train_f)
        constant = np.broadcast_to(train_y.mean(axis=0, keepdims=True), y.shape)
        baseline = training.angle_errors_deg(constant, y, data.output_grid)
        self.assertLess(errors["mean_deg"], 0.7 * baseline["mean_deg"],
                        f"model {errors['mean_deg']:.2f} deg vs constant {baseline['mean_deg']:.2f} deg")

    def test_finetune(self):
        out = os.path.join(self.tmp, "tuned.onnx")
        code, log, err = run(finetune.main, ["--model", self.unet[:-5] + ".pt", "--data", self.data,
                                             "--subject", "2", "--minutes", "0.2", "--epochs", "2", "--threads", "1",
                                             "--out", out])
        self.assertEqual(code, 0, err)
        with open(out[:-5] + ".json") as f:
            sidecar = json.load(f)
        self.assertTrue(sidecar["finetuned_from"]["path"].endswith("unet.pt"))
        self.assertEqual(sidecar["training"]["data"]["subjects"], [2])
        self.assertLessEqual(sidecar["training"]["best_val_deg"], sidecar["training"]["val_deg_before"])
        self.assertIn("held-out personal error", log)

    def test_evaluate_tiny(self):
        out_json = os.path.join(self.tmp, "eval.json")
        out_md = os.path.join(self.tmp, "eval.md")
        code, _, err = run(evaluate.main, ["--data", self.data, "--epochs", "1", "--unet-width", "4",
                                           "--finetune-epochs", "1", "--finetune-minutes", "0.1",
                                           "--finetune-lr", "1e-4,1e-6", "--ablation", "--threads", "1",
                                           "--quiet", "--out-json", out_json, "--out-md", out_md])
        self.assertEqual(code, 0, err)
        with open(out_json) as f:
            report = json.load(f)
        self.assertEqual(sorted(report["subjects"]), ["0", "1", "2"])
        for row in report["subjects"].values():
            self.assertEqual(sorted(row["scenarios"]), ["1", "2", "3", "4", "5", "6"])
            self.assertEqual(len(row["scenarios"]["4"]["per_dof_deg"]), 20)
        self.assertEqual([s["cells"] for s in report["ablation"]["stages"]], [14, 18, 29, 44])
        self.assertEqual([(e["scenario"], e["lr"]) for e in report["finetune_sweep"]],
                         [(5, 1e-4), (5, 1e-6), (6, 1e-4), (6, 1e-6)])
        with open(out_md) as f:
            md = f.read()
        self.assertIn("| **average** |", md)
        self.assertIn("not real-world accuracy", md)

    def test_errors_are_clear(self):
        code, _, err = run(train.main, ["--data", self.data, "--out", os.path.join(self.tmp, "model.bin")])
        self.assertEqual(code, 2)
        self.assertIn("must end in .onnx", err)
        code, _, err = run(train.main, ["--data", os.path.join(self.tmp, "nowhere"), "--out", self.unet])
        self.assertEqual(code, 2)
        self.assertIn("not a directory", err)
        code, _, err = run(train.main, ["--data", self.data, "--subjects", "7", "--out",
                                        os.path.join(self.tmp, "none.onnx")])
        self.assertEqual(code, 2)
        self.assertIn("leaves no training sessions", err)
        code, _, err = run(finetune.main, ["--model", os.path.join(self.tmp, "missing.pt"), "--data", self.data,
                                           "--subject", "0", "--out", os.path.join(self.tmp, "x.onnx")])
        self.assertEqual(code, 2)
        self.assertIn("missing.pt", err)


if __name__ == "__main__":
    unittest.main()
