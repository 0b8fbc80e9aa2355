#!/usr/bin/python3
"""Regenerates the generic stretch-glove pose model from a seed, in one command:
simulates the training subjects with `proprio sim-glove`, then trains with
train.py. Same seed, same proprio build, same torch build and thread count ->
the same model.onnx, byte for byte.

  /usr/bin/python3 tools/stretch_glove/make_generic_model.py \\
      --proprio build/dev/tools/proprio/proprio --seed 1 --out models/stretch_glove/generic_unet.onnx

The model is trained for scenario 4 of the thesis (each wearer calibrates with
a short exploration phase) unless --calibration global (scenario 3). It is
trained on simulated hands only: its accuracy on a real glove is unknown.
"""

import argparse
import os
import shlex
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def run(cmd):
    print("+ " + " ".join(shlex.quote(c) for c in cmd), flush=True)
    return subprocess.run(cmd, check=False).returncode


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--proprio", required=True, help="path of the proprio CLI (e.g. build/dev/tools/proprio/proprio)")
    p.add_argument("--out", required=True, help="the model's NAME.onnx (NAME.json, NAME.pt next to it)")
    p.add_argument("--seed", type=int, default=1, help="seeds the simulation and the training (default 1)")
    p.add_argument("--subjects", type=int, default=15, help="simulated subjects (default 15, the simulator's pool)")
    p.add_argument("--sessions", type=int, default=3, help="sessions (donnings) per subject (default 3)")
    p.add_argument("--minutes", type=float, default=5.0, help="task motion per session (default 5)")
    p.add_argument("--exploration-seconds", type=float, default=60.0, help="calibration phase per session (default 60)")
    p.add_argument("--model", choices=["unet", "fcn"], default="unet")
    p.add_argument("--calibration", choices=["session", "global"], default="session")
    p.add_argument("--epochs", type=int, default=40)
    p.add_argument("--patience", type=int, default=6)
    p.add_argument("--max-train-frames", type=int, default=200000,
                   help="every k-th training frame so at most this many remain (default 200000)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (the result depends on it; default 2)")
    p.add_argument("--data", help="where the simulated dataset goes (default: next to --out, removed afterwards)")
    p.add_argument("--keep-data", action="store_true", help="keep the simulated dataset")
    a = p.parse_args(argv)
    if not a.out.endswith(".onnx"):
        print(f"error: --out '{a.out}' must end in .onnx", file=sys.stderr)
        return 2
    if not (os.path.isfile(a.proprio) and os.access(a.proprio, os.X_OK)):
        print(f"error: --proprio '{a.proprio}' is not an executable file; build it first "
              "(cmake --build build/dev --target proprio)", file=sys.stderr)
        return 2
    data = a.data or a.out[: -len(".onnx")] + "_simulated_data"
    started = time.time()
    code = run([a.proprio, "sim-glove", "--subjects", str(a.subjects), "--sessions", str(a.sessions),
                "--minutes", str(a.minutes), "--exploration-seconds", str(a.exploration_seconds),
                "--seed", str(a.seed), "--out", data, "--force"])
    if code != 0:
        print(f"error: proprio sim-glove failed (exit {code})", file=sys.stderr)
        return code
    simulated = time.time()
    code = run([sys.executable, os.path.join(HERE, "train.py"), "--data", data, "--model", a.model,
                "--calibration", a.calibration, "--seed", str(a.seed), "--epochs", str(a.epochs),
                "--patience", str(a.patience), "--max-train-frames", str(a.max_train_frames),
                "--threads", str(a.threads), "--out", a.out])
    if not a.keep_data and not a.data:
        shutil.rmtree(data, ignore_errors=True)
    if code != 0:
        print(f"error: train.py failed (exit {code})", file=sys.stderr)
        return code
    print(f"generic model {a.out}: simulation {simulated - started:.0f} s, training {time.time() - simulated:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
