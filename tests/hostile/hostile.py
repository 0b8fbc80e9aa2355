#!/usr/bin/env python3
"""The hostile-input suite: runs the built CLI (and OpenXR apps through the layer)
against malformed bytes, special files, NaN and inf, clashing processes and
crashes, and asserts what a user must get: the exit code, a message that says
what is wrong, no hang, bounded memory, and no data changed.

Cases live in tests/hostile/cases_*.py, one file per area; every case is a
function decorated with @case. Each runs in a fresh folder of its own.

    python3 tests/hostile/hostile.py --cli build/dev/tools/proprio/proprio \
        --work /tmp/hostile [--mock-runtime-json J --layer-dir D] cases_cli.py ...
    add -k SUBSTRING to run only matching cases, --list to list them.

A case that cannot run here (say, no OpenXR loader) is reported as SKIPPED
with the reason, and is never counted as passed.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

CASES: list[tuple[str, str, Callable]] = []  # (file stem, name, function)
_current_file = ""


def case(name: str):
    """Registers a case: `def _(t: Ctx)` with a name that says what must hold."""
    def register(fn):
        CASES.append((_current_file, name, fn))
        return fn
    return register


class CaseFailed(Exception):
    pass


class Skip(Exception):
    pass


@dataclass
class Run:
    args: list[str]
    rc: int
    out: str
    err: str
    seconds: float
    timed_out: bool

    def describe(self) -> str:
        tail = lambda s: s[-1500:] if len(s) > 1500 else s
        return (f"$ {' '.join(self.args)}\n  exit {self.rc}{' (TIMED OUT)' if self.timed_out else ''} in "
                f"{self.seconds:.1f} s\n"
                f"  stdout: {tail(self.out)!r}\n  stderr: {tail(self.err)!r}")

    def expect(self, rc: int | set[int] | None = None, err: str | None = None, out: str | None = None,
               no_err: str | None = None) -> "Run":
        """rc: the exit status (or a set of them); err/out: regexes the output must
        match (case-insensitive); no_err: one stderr must not match."""
        if self.timed_out:
            raise CaseFailed("did not finish (hang)\n" + self.describe())
        if self.rc < 0 or self.rc >= 128:
            raise CaseFailed(f"crashed (signal {-self.rc if self.rc < 0 else self.rc - 128})\n" + self.describe())
        if rc is not None:
            ok = self.rc in rc if isinstance(rc, set) else self.rc == rc
            if not ok:
                raise CaseFailed(f"expected exit {rc}, got {self.rc}\n" + self.describe())
        if err is not None and not re.search(err, self.err, re.I | re.S):
            raise CaseFailed(f"stderr does not match /{err}/\n" + self.describe())
        if out is not None and not re.search(out, self.out, re.I | re.S):
            raise CaseFailed(f"stdout does not match /{out}/\n" + self.describe())
        if no_err is not None and re.search(no_err, self.err, re.I | re.S):
            raise CaseFailed(f"stderr matches /{no_err}/, which it must not\n" + self.describe())
        return self

    def fails_cleanly(self, err: str) -> "Run":
        """The common expectation: exit 1, a message matching `err`, no crash."""
        return self.expect(rc=1, err=err)


@dataclass
class Ctx:
    dir: Path
    cli: str
    env: dict[str, str]
    opts: argparse.Namespace
    _hashes: dict[Path, str] = field(default_factory=dict)

    def path(self, name: str) -> Path:
        return self.dir / name

    def write(self, name: str, data: bytes | str) -> Path:
        p = self.path(name)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data.encode() if isinstance(data, str) else data)
        return p

    def fifo(self, name: str) -> Path:
        p = self.path(name)
        os.mkfifo(p)
        return p

    def watch(self, *names: str | Path) -> None:
        """Remembers files (or every file under a folder) that must not change."""
        for n in names:
            p = n if isinstance(n, Path) else self.path(n)
            files = [f for f in sorted(p.rglob("*")) if f.is_file()] if p.is_dir() else [p]
            for f in files:
                self._hashes[f] = _digest(f)

    def unchanged(self) -> None:
        for f, h in self._hashes.items():
            now = _digest(f)
            if now != h:
                raise CaseFailed(f"{f.name} changed (or vanished): data lost")

    def need(self, cond: bool, why: str) -> None:
        if not cond:
            raise Skip(why)

    def layer_status(self, config: str) -> "Run":
        """`proprio layer status` on this layer configuration (TOML text)."""
        return self.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(self.write("layer.toml", config))})

    def layer_env(self, config: str | Path, extra: dict[str, str] | None = None) -> dict[str, str]:
        """An app's environment: the mock runtime, Proprio's layer enabled, and this layer configuration (TOML
        text, or a path used as it is). Skips the case when the runtime or the layer was not built."""
        self.need(bool(self.opts.mock_runtime_json) and Path(self.opts.mock_runtime_json).exists(),
                  "no mock OpenXR runtime manifest (--mock-runtime-json)")
        self.need(bool(self.opts.layer_dir) and Path(self.opts.layer_dir).is_dir(), "no built layer (--layer-dir)")
        path = config if isinstance(config, Path) else self.write("layer.toml", config)
        env = {"XR_RUNTIME_JSON": str(Path(self.opts.mock_runtime_json).resolve()),
               "XR_API_LAYER_PATH": str(Path(self.opts.layer_dir).resolve()),
               "XR_ENABLE_API_LAYERS": "XR_APILAYER_PROPRIO_hand_tracking",
               "PROPRIO_LAYER_CONFIG": str(path)}
        env.update(extra or {})
        return env

    def run(self, *args: str | Path, env: dict[str, str] | None = None, timeout: float = 60.0,
            max_mb: int = 2048, stdin: bytes | None = None, cli: bool = True) -> Run:
        """Runs the CLI (or, with cli=False, any program) in the case folder, with
        an address-space cap of max_mb, and kills it after `timeout` s."""
        argv = ([self.cli] if cli else []) + [str(a) for a in args]
        full_env = dict(self.env)
        full_env.update(env or {})
        limit = max_mb * 1024 * 1024

        def cap():
            os.setsid()
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))

        start = time.monotonic()
        p = subprocess.Popen(argv, cwd=self.dir, env=full_env, stdin=subprocess.PIPE if stdin is not None
                             else subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             preexec_fn=cap)
        timed_out = False
        try:
            out, err = p.communicate(input=stdin, timeout=timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            os.killpg(p.pid, signal.SIGKILL)
            out, err = p.communicate()
        shown = ["P" if cli and i == 0 else a for i, a in enumerate(argv)]
        return Run(shown, p.returncode, out.decode(errors="replace"), err.decode(errors="replace"),
                   time.monotonic() - start, timed_out)

    def start(self, *args: str | Path, env: dict[str, str] | None = None) -> subprocess.Popen:
        """Starts the CLI in the background (for races and crashes); the caller waits or kills."""
        full_env = dict(self.env)
        full_env.update(env or {})
        return subprocess.Popen([self.cli] + [str(a) for a in args], cwd=self.dir, env=full_env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)


def _digest(p: Path) -> str:
    if not p.exists():
        return "<missing>"
    h = hashlib.sha256()
    with open(p, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def load_cases(files: list[str]) -> None:
    global _current_file
    here = Path(__file__).resolve().parent
    # Case files `from hostile import case`: that must be this very module,
    # not a second copy with its own CASES, when this file runs as __main__.
    sys.modules.setdefault("hostile", sys.modules[__name__])
    for name in files:
        path = Path(name) if Path(name).exists() else here / name
        _current_file = path.stem
        spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cli", required=True, help="the built proprio executable")
    ap.add_argument("--work", required=True, help="scratch folder (emptied first)")
    ap.add_argument("--mock-runtime-json", default="", help="the mock OpenXR runtime's manifest")
    ap.add_argument("--layer-dir", default="", help="folder of the built layer's manifest")
    ap.add_argument("--source-dir", default=str(Path(__file__).resolve().parents[2]))
    ap.add_argument("-k", default="", help="run only cases whose name contains this")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("files", nargs="+")
    opts = ap.parse_args()
    opts.cli = str(Path(opts.cli).resolve())
    load_cases(opts.files)
    selected = [c for c in CASES if opts.k.lower() in c[1].lower()]
    if opts.list:
        for f, n, _ in selected:
            print(f"{f}: {n}")
        return 0
    if not selected:
        print("error: no case selected", file=sys.stderr)
        return 1
    work = Path(opts.work)
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("XR_", "PROPRIO_"))}
    env["HOME"] = str(work / "home")  # the layer's user config, installs: never the real ones
    env["XDG_CONFIG_HOME"] = str(work / "home" / ".config")
    env["XDG_DATA_HOME"] = str(work / "home" / ".local" / "share")
    (work / "home").mkdir()
    passed, failed, skipped = [], [], []
    for i, (f, name, fn) in enumerate(selected):
        d = work / f"{i:03d}"
        d.mkdir()
        t = Ctx(d, opts.cli, env, opts)
        start = time.monotonic()
        try:
            fn(t)
            t.unchanged()
            passed.append(name)
            status = "ok"
        except Skip as e:
            skipped.append((name, str(e)))
            status = f"SKIPPED: {e}"
        except CaseFailed as e:
            failed.append((name, str(e)))
            status = "FAILED"
        except Exception:  # a bug in the case itself is a failure too
            failed.append((name, traceback.format_exc()))
            status = "FAILED (case error)"
        print(f"[{i + 1:3d}/{len(selected)}] {status:<8} {name} ({time.monotonic() - start:.1f} s)", flush=True)
    for name, why in failed:
        print(f"\n--- FAILED: {name}\n{why}")
    print(f"\nhostile inputs: {len(passed)} passed, {len(failed)} failed, {len(skipped)} skipped "
          f"of {len(selected)} cases")
    for name, why in skipped:
        print(f"  skipped: {name}: {why}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
