"""Hostile inputs for the CLI's shared mechanisms: numeric options, seeds, config
and data files that are special files, unknown keys, device paths, the OpenXR
layer's config and status, exit codes and messages (issue 23)."""
import os
import re

from hostile import case

SIM_HAND_NAN = ["sim-hand", "--seconds", "nan", "--out", "x.prec"]

# --- 23.7: NaN and inf never pass a numeric option -------------------------------------


@case("23.7 sim-hand --seconds nan is refused before anything is written")
def _(t):
    t.run(*SIM_HAND_NAN).fails_cleanly(r"--seconds.*'nan' is not a finite number")
    assert not t.path("x.prec").exists(), "a recording was written for a NaN duration"


@case("23.7 sim-hand --seconds inf / -inf / 1e999 are refused")
def _(t):
    for v in ("inf", "-inf", "1e999", "infinity"):
        t.run("sim-hand", "--seconds", v, "--out", "x.prec").fails_cleanly(r"not a finite number|not in range")


@case("23.7 replay --replay-rate nan is refused, no hang")
def _(t):
    t.run("sim-hand", "--seconds", "1", "--out", "a.prec").expect(rc=0)
    t.watch("a.prec")
    t.run("replay", "a.prec", "--replay-rate", "nan", timeout=20).fails_cleanly(r"not a finite number")


@case("23.7 xr-probe --seconds nan is refused, no hang")
def _(t):
    t.run("xr-probe", "--seconds", "nan", timeout=20).fails_cleanly(r"--seconds.*not a finite number")


@case("23.7 glove monitor --seconds nan is refused, no hang")
def _(t):
    t.run("glove", "monitor", "--seconds", "nan", timeout=20).fails_cleanly(r"not a finite number")


@case("23.7 haptics test --seconds nan / --force nan are refused, no hang")
def _(t):
    t.run("haptics", "test", "--device", "emulated", "--seconds", "nan", timeout=20).fails_cleanly(r"finite")
    t.run("haptics", "test", "--device", "emulated", "--force", "nan", timeout=20).fails_cleanly(r"finite")


@case("23.7 a number with trailing garbage is refused")
def _(t):
    t.run("sim-hand", "--seconds", "3s", "--out", "x.prec").fails_cleanly(r"3s")


# --- 23.18: seeds never wrap or clamp ---------------------------------------------------


@case("23.18 --seed -1, 1e23, 0x10 and 2^64 are refused; 2^64-1 is a seed of its own")
def _(t):
    for bad in ("-1", "1e23", "0x10", "18446744073709551616", "1.5", "010 "):
        t.run("sim-hand", "--seconds", "1", "--seed", bad, "--out", "x.prec").fails_cleanly(r"--seed")
    assert not t.path("x.prec").exists()
    t.run("sim-hand", "--seconds", "1", "--seed", "18446744073709551615", "--out", "max.prec").expect(rc=0)
    t.run("sim-hand", "--seconds", "1", "--seed", "1", "--out", "one.prec").expect(rc=0)
    assert t.path("max.prec").read_bytes() != t.path("one.prec").read_bytes(), "seed 2^64-1 gave seed 1's file"


# --- 23.5: special files are refused, never read without bounds -------------------------


@case("23.5 the layer config as /dev/zero: refused at once, bounded")
def _(t):
    r = t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": "/dev/zero"}, timeout=20, max_mb=1024)
    r.expect(rc={1, 2}, out=r"is a character device")


@case("23.5 the layer config as a FIFO: refused, no hang")
def _(t):
    fifo = t.fifo("layer.toml")
    t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(fifo)}, timeout=20).expect(rc={1, 2}, out=r"FIFO")


@case("23.5 the layer config as a directory says so")
def _(t):
    os.mkdir(t.path("cfgdir"))
    t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(t.path("cfgdir"))}, timeout=20).expect(
        rc={1, 2}, out=r"is a directory")


@case("23.5 glove monitor --from-file /dev/zero and a FIFO are refused")
def _(t):
    t.run("glove", "monitor", "--from-file", "/dev/zero", timeout=20, max_mb=1024).fails_cleanly(r"character device")
    fifo = t.fifo("cap.bin")
    t.run("glove", "monitor", "--from-file", fifo, timeout=20).fails_cleanly(r"FIFO")


@case("23.5 stretch-board monitor --from-file /dev/zero and a FIFO are refused")
def _(t):
    t.run("stretch-board", "monitor", "--from-file", "/dev/zero", timeout=20, max_mb=1024).fails_cleanly(
        r"character device")
    fifo = t.fifo("cap.bin")
    t.run("stretch-board", "monitor", "--from-file", fifo, timeout=20).fails_cleanly(r"FIFO")


# --- 25: damaged capture files (hid::CaptureReader behind both monitors) ------------------

CAPTURE_MONITORS = [("glove", r"no IMU data"), ("stretch-board", r"no measurements")]


def damaged_captures(t, board: str) -> dict[str, bytes]:
    """A clean 2 s capture of `board`, and the ways a capture arrives broken."""
    t.run(board, "emulate", "--out", f"{board}.bin", "--seconds", "2", "--force", timeout=60).expect(rc=0)
    clean = t.path(f"{board}.bin").read_bytes()
    noise = bytes((i * 167 + 13) % 256 for i in range(5000))
    return {
        "garbage_prefix": noise[:37] + clean,
        "torn_end": clean[:-23],
        "shifted": clean[:1000] + clean[1003:],
        "hole": clean[:2000] + bytes(4096) + clean[2000:],
        "garbage_inside": clean[:3000] + noise + clean[3000:],
    }


@case("25 monitor --from-file resynchronises after damage and says how many bytes it skipped")
def _(t):
    for board, _ in CAPTURE_MONITORS:
        for name, data in damaged_captures(t, board).items():
            t.write(f"{board}_{name}.bin", data)
            r = t.run(board, "monitor", "--from-file", f"{board}_{name}.bin", timeout=30)
            r.expect(rc=0, out=rf"{len(data)} bytes, .* s of device time")
            if name != "torn_end":
                r.expect(out=r"bytes skipped to resynchronise")


@case("25 monitor --from-file on noise, one ID byte repeated, one byte, or nothing: exit 1, no crash")
def _(t):
    for board, no_data in CAPTURE_MONITORS:
        for name, data in {"noise": bytes((i * 31 + 7) % 256 for i in range(20000)), "ids": b"\x01" * 4096,
                           "ids21": b"\x21" * 4096, "one": b"\x01", "empty": b""}.items():
            t.write(f"{name}.bin", data)
            t.run(board, "monitor", "--from-file", f"{name}.bin", timeout=30).expect(rc=1, out=no_data)


@case("25 monitor --from-file streams: 300 MiB of zeros in a 512 MiB address space")
def _(t):
    # Reading the whole file (as before issue 25) needed twice its size and
    # died of bad_alloc here, even under a 768 MiB cap.
    p = t.path("zeros.bin")
    with open(p, "wb") as f:
        f.truncate(300 * 1024 * 1024)  # sparse
    for board, no_data in CAPTURE_MONITORS:
        t.run(board, "monitor", "--from-file", p, timeout=60, max_mb=512).expect(
            rc=1, out=r"314572800 bytes.*" + no_data)


@case("25 monitor --from-file refuses a capture above 1 GiB at once, with its size and the limit")
def _(t):
    p = t.path("huge.bin")
    with open(p, "wb") as f:
        f.truncate(1024 * 1024 * 1024 + 1)  # sparse
    for board, _ in CAPTURE_MONITORS:
        t.run(board, "monitor", "--from-file", p, timeout=20).fails_cleanly(r"too large.*limit")


@case("23.5 a glove description, layout or device model that is a FIFO or /dev/zero is refused")
def _(t):
    fifo = t.fifo("g.toml")
    t.run("sim-vist", "--glove", fifo, "--seconds", "1", "--out", "s.prec", timeout=30).fails_cleanly(r"FIFO")
    t.run("sim-vist", "--glove", "/dev/zero", "--seconds", "1", "--out", "s.prec", timeout=30).fails_cleanly(
        r"character device")
    t.run("haptics", "test", "--device", "emulated", "--model", fifo, timeout=30).fails_cleanly(r"FIFO")
    t.run("calibrate", "glove", "--layout", fifo, "--out", "c.toml", timeout=30).fails_cleanly(r"FIFO")


@case("23.5 a scene file that is a FIFO is refused")
def _(t):
    fifo = t.fifo("scene.toml")
    t.run("run", fifo, "--headless", "--frames", "1", "--out", "f", timeout=30).fails_cleanly(r"FIFO")


@case("23.5 a huge config file is refused with its size and the limit")
def _(t):
    p = t.path("big.toml")
    with open(p, "wb") as f:
        f.truncate(20 * 1024 * 1024)  # sparse: 20 MiB of zeros
    t.run("haptics", "test", "--device", "emulated", "--model", p, timeout=30).fails_cleanly(r"too large.*limit")


# --- 23.4: device paths that are not hidraw nodes ---------------------------------------


@case("23.4 glove/stretch-board monitor --path /dev/null, /dev/zero, a file: clear error, no crash")
def _(t):
    t.write("plain", b"\0" * 64)
    for cmd in (["glove", "monitor"], ["stretch-board", "monitor"]):
        for p in ("/dev/null", "/dev/zero", str(t.path("plain")), str(t.path("missing"))):
            t.run(*cmd, "--path", p, "--seconds", "1", timeout=30).expect(
                rc=1, err=r"hidraw|does not exist")


@case("23.4 haptics test --device /dev/null, /dev/zero: clear error, no crash")
def _(t):
    for p in ("/dev/null", "/dev/zero"):
        t.run("haptics", "test", "--device", p, "--seconds", "1", timeout=30).expect(rc=1, err=r"hidraw")


# --- 23.13: unknown keys are errors in every TOML file ----------------------------------


@case("23.13 a scene with [[objects]] (for [[object]]) is refused with file:line")
def _(t):
    t.write("scene.toml", 'name = "s"\n[[objects]]\nname = "box"\nshape = "box"\n')
    t.run("run", "scene.toml", "--headless", "--frames", "1", "--out", "f", timeout=60).fails_cleanly(
        r"scene.toml:2:.*unknown key 'objects'")


@case("23.13 a scene object with a typo'd key is refused")
def _(t):
    t.write("scene.toml", '[[object]]\nname = "box"\nshape = "box"\nposition = [0, 1, 0]\nmas = 2\n')
    t.run("run", "scene.toml", "--headless", "--frames", "1", "--out", "f", timeout=60).fails_cleanly(
        r"scene.toml:5:.*unknown key 'mas'")


@case("23.13 the layer config with [[sources]] or a typo'd key: layer status is not OK")
def _(t):
    t.write("a.toml", '[[sources]]\ntype = "sim"\n')
    t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(t.path("a.toml"))}).expect(
        rc={1, 2}, out=r"a.toml:1:.*unknown key 'sources'", no_err=r".")
    t.write("b.toml", '[[source]]\ntype = "sim"\nsubjekt = 4\n')
    t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(t.path("b.toml"))}).expect(
        rc={1, 2}, out=r"b.toml:3:.*unknown key 'subjekt'")
    t.write("c.toml", '[layer]\nmax_prediction = 20\n')
    t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(t.path("c.toml"))}).expect(
        rc={1, 2}, out=r"unknown key 'max_prediction'")


# --- 23.15: the layer's readiness ---------------------------------------------------------


def _replay_config(t, path):
    t.write("layer.toml", f'[[source]]\ntype = "replay"\npath = "{path}"\n')
    return {"PROPRIO_LAYER_CONFIG": str(t.path("layer.toml"))}


@case("23.15 layer status: a missing, empty, FIFO or garbage replay file is a problem, not OK")
def _(t):
    t.write("empty.prec", b"")
    t.write("junk.prec", b"not a recording at all\n" * 10)
    fifo = t.fifo("fifo.prec")
    for name, why in (("missing.prec", r"does not exist"), ("empty.prec", r"."), ("fifo.prec", r"FIFO"),
                      ("junk.prec", r".")):
        r = t.run("layer", "status", env=_replay_config(t, t.path(name)), timeout=20)
        r.expect(out=r"Problem: \[\[source\]\] #1 \(replay\) cannot serve hands: .*" + why)
        assert r.rc != 0, f"layer status exit 0 with a replay source {name}"
    assert fifo.exists()


@case("23.15 an offset that would make an invalid pose is refused in the config")
def _(t):
    t.write("layer.toml", '[[source]]\ntype = "sim"\noffset_position_m = [1e300, 0, 0]\n')
    t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(t.path("layer.toml"))}).expect(
        rc={1, 2}, out=r"layer.toml:3:.*offset_position_m.*within")
    t.write("layer.toml", '[[source]]\ntype = "sim"\noffset_rotation_deg = [nan, 0, 0]\n')
    t.run("layer", "status", env={"PROPRIO_LAYER_CONFIG": str(t.path("layer.toml"))}).expect(
        rc={1, 2}, out=r"finite")


# --- 23.17: init-config with a bare file name -------------------------------------------


@case("23.17 layer init-config --out NAME writes NAME in the current folder")
def _(t):
    t.run("layer", "init-config", "--out", "layer.toml").expect(rc=0)
    assert t.path("layer.toml").is_file()
    t.watch("layer.toml")
    t.run("layer", "init-config", "--out", "layer.toml").fails_cleanly(r"already exists.*--force")


@case("23.17 layer init-config --out a directory or a FIFO is refused, nothing lost")
def _(t):
    os.mkdir(t.path("d"))
    t.run("layer", "init-config", "--out", "d", "--force").fails_cleanly(r"is a directory")
    fifo = t.fifo("f")
    t.run("layer", "init-config", "--out", fifo, "--force", timeout=20).fails_cleanly(r"FIFO")


# --- 23.19: exit codes and messages -------------------------------------------------------


@case("23.19 a bad option value exits 1 (documented), not CLI11's 105")
def _(t):
    t.run("sim-hand", "--seconds", "abc", "--out", "x.prec").expect(rc=1)
    t.run("sim-hand", "--no-such-option").expect(rc=1)
    t.run("sim-hand").expect(rc=1, err=r"--out")  # a required option is missing
    t.run("--help").expect(rc=0, out=r"Exit status: 0 success; 1")


@case("23.19 proprio --version ends with a newline")
def _(t):
    r = t.run("--version").expect(rc=0, out=r"^proprio \d")
    assert r.out.endswith("\n"), repr(r.out)


@case("23.19 a 100 kB option value is not echoed back whole")
def _(t):
    big = "9" * 100_000  # near the kernel's limit for one argument (128 KiB)
    r = t.run("sim-hand", "--seconds", "1", "--seed", big, "--out", "x.prec").expect(rc=1)
    assert len(r.err) < 4096, f"{len(r.err)} bytes of error output"


@case("23.19 control characters in a file name do not reach the terminal raw")
def _(t):
    name = "evil\x1b[2J\x1b]0;pwned\x07.toml"
    r = t.run("haptics", "test", "--device", "emulated", "--model", name, timeout=30).expect(rc=1)
    assert "\x1b" not in r.err and "\x07" not in r.err, repr(r.err)


# --- 23.5 / 23.15: the layer inside an app ------------------------------------------------


def _app_env(t, config):
    t.need(bool(t.opts.mock_runtime_json) and os.path.exists(t.opts.mock_runtime_json), "no mock OpenXR runtime built")
    t.need(bool(t.opts.layer_dir) and os.path.isdir(t.opts.layer_dir), "no OpenXR layer built")
    return {"XR_RUNTIME_JSON": t.opts.mock_runtime_json, "XR_API_LAYER_PATH": t.opts.layer_dir,
            "XR_ENABLE_API_LAYERS": "XR_APILAYER_PROPRIO_hand_tracking", "PROPRIO_LAYER_CONFIG": str(config)}


@case("23.5 an app whose layer config is /dev/zero starts at once, bounded, and says why it has no hands")
def _(t):
    r = t.run("xr-probe", "--seconds", "1", env=_app_env(t, "/dev/zero"), timeout=30, max_mb=1536)
    r.expect(err=r"character device")
    assert r.seconds < 20, f"the app took {r.seconds:.1f} s"


@case("23.5 an app whose layer config or replay file is a FIFO does not hang")
def _(t):
    fifo = t.fifo("layer.toml")
    t.run("xr-probe", "--seconds", "1", env=_app_env(t, fifo), timeout=30).expect(err=r"FIFO")
    rec = t.fifo("rec.prec")
    t.write("replay.toml", f'[[source]]\ntype = "replay"\npath = "{rec}"\n')
    t.run("xr-probe", "--seconds", "1", env=_app_env(t, t.path("replay.toml")), timeout=30).expect(err=r"FIFO")
    vist = t.write("vist.toml", f'[[source]]\ntype = "vist"\npath = "{rec}"\n')
    t.run("xr-probe", "--seconds", "1", env=_app_env(t, vist), timeout=30).expect(err=r"FIFO")


@case("23.5 a glTF hand or a stereo calibration that is a FIFO is refused, no hang")
def _(t):
    fifo = t.fifo("hand.gltf")
    t.run("run", "half-cylinder", "--headless", "--frames", "1", "--hand-look", fifo, "--out", "f",
          timeout=60).fails_cleanly(r"FIFO")
    cal = t.fifo("stereo.yaml")
    t.run("track", "vist", "--live", "--calibration", cal, "--seconds", "1", timeout=60).expect(rc=1, err=r"FIFO")


@case("layer install --force replaces a different manifest it had to read first")
def _(t):
    env = {"XDG_DATA_HOME": str(t.path("data")), "HOME": str(t.path("home"))}
    t.run("layer", "install", "--user", env=env).expect(rc=0)
    manifests = list(t.path("data").rglob("*.json"))
    assert len(manifests) == 1, manifests
    manifests[0].write_text('{"file_format_version": "1.0.0", "api_layer": {"name": "other", "library_path": "x.so"}}')
    t.watch(manifests[0])
    t.run("layer", "install", "--user", env=env).fails_cleanly(r"already exists.*--force")
    t.unchanged()
    t._hashes.clear()
    t.run("layer", "install", "--user", "--force", env=env).expect(rc=0, out=r"Installed")
    assert "XR_APILAYER_PROPRIO" in manifests[0].read_text()


@case("23.5 a glTF whose buffer is a FIFO or /dev/zero is refused, no hang, bounded")
def _(t):
    t.fifo("buf.bin")
    for uri in ("buf.bin", "/dev/zero"):
        t.write("hand.gltf", '{"asset": {"version": "2.0"}, "buffers": [{"uri": "%s", "byteLength": 1000000000}]}'
                % uri)
        t.run("run", "half-cylinder", "--headless", "--frames", "1", "--hand-look", "hand.gltf", "--out", "f",
              timeout=60, max_mb=1536).fails_cleanly(r"FIFO|character device")


# --- issue 25: `proprio` hands heavy commands to the family programs in libexec ----------


@case("25 a family program missing from PROPRIO_LIBEXEC_DIR: exit 1 naming the path looked at")
def _(t):
    empty = t.path("libexec")
    empty.mkdir()
    env = {"PROPRIO_LIBEXEC_DIR": str(empty)}
    for args, program in ((["run", "--help"], "proprio-engine"), (["haptics", "mjcf"], "proprio-haptics"),
                          (["bench", "vist", "--help"], "proprio-trackers"),
                          (["glove", "list"], "proprio-devices")):
        t.run(*args, env=env, timeout=20).fails_cleanly(
            re.escape(str(empty / program)) + r".*PROPRIO_LIBEXEC_DIR")


@case("25 a family program that is a FIFO, a folder or not executable: refused with what it is, no hang")
def _(t):
    d = t.path("libexec")
    d.mkdir()
    env = {"PROPRIO_LIBEXEC_DIR": str(d)}
    os.mkfifo(d / "proprio-engine")
    t.run("run", "--help", env=env, timeout=20).fails_cleanly(r"proprio-engine: a FIFO")
    (d / "proprio-haptics").mkdir()
    t.run("haptics", "mjcf", env=env, timeout=20).fails_cleanly(r"proprio-haptics: a folder")
    (d / "proprio-trackers").write_text("#!/bin/sh\necho ran\n")
    os.chmod(d / "proprio-trackers", 0o644)
    t.run("sim-vist", "--help", env=env, timeout=20).fails_cleanly(r"proprio-trackers: not executable")


@case("25 proprio's own commands and --help need no family program and load no OpenCV, Vulkan or MuJoCo")
def _(t):
    env = {"PROPRIO_LIBEXEC_DIR": str(t.path("nowhere"))}
    t.run("--help", env=env).expect(rc=0, out=r"(?s)sim-hand.*bench.*stretch-board.*haptics.*psychometric.*xr-probe")
    t.run("bench", "--help", env=env).expect(rc=0, out=r"(?s)vist .*glove .*haptics .*Time the MuJoCo step")
    t.write("d.csv", "level,correct,trials\n1,6,10\n2,7,10\n3,9,10\n4,10,10\n")
    r = t.run("psychometric", "fit", "--data", "d.csv", env={**env, "LD_DEBUG": "files"})
    r.expect(rc=0, out=r"threshold at 0\.75", no_err=r"opencv|libvulkan|mujoco|hidapi|openxr_loader")


@case("25 an unknown command or subcommand is a usage error (exit 1), not an attempt to start a program")
def _(t):
    t.run("no-such-command", timeout=20).fails_cleanly(r"subcommand is required|not expected")
    t.run("bench", "no-such-bench", timeout=20).fails_cleanly(r"subcommand is required|not expected")
    t.run("--log-level", timeout=20).fails_cleanly(r"--log-level")


@case("25 --log-level before a heavy command reaches its program; argv[0] and exit codes pass through")
def _(t):
    t.run("--log-level", "debug", "haptics", "mjcf", timeout=60).expect(rc=0, out=r"^<mujoco")
    t.run("--log-level=warn", "haptics", "mjcf", timeout=60).expect(rc=0, out=r"^<mujoco")
    t.run("--log-level", "bogus", "haptics", "mjcf", timeout=60).fails_cleanly(r"unknown log level 'bogus'")
    r = t.run("--log-level", "error", "run", "--help", timeout=60).expect(rc=0, out=r"Usage: \S*proprio run ")
    assert "proprio-engine" not in r.out, "the family program's name leaked into the usage line"
    t.run("glove", "monitor", "--seconds", "nan", timeout=20).fails_cleanly(r"not a finite number")


# --- 25: the installed data folder ($PROPRIO_DATA_DIR) -----------------------------------


@case("25 PROPRIO_DATA_DIR as /dev/zero, a FIFO, a missing path: said once, never another folder, no hang")
def _(t):
    fifo = t.fifo("data")
    for bad, what in (("/dev/zero", "/dev/zero"), (str(fifo), "FIFO|data"), (str(t.path("missing")), "missing")):
        r = t.run("haptics", "sim", env={"PROPRIO_DATA_DIR": bad}, timeout=30)
        r.fails_cleanly(r"PROPRIO_DATA_DIR is set to")
        assert re.search(what, r.err or ""), f"the message does not name {bad}"


@case("25 PROPRIO_DATA_DIR as an empty folder: the missing file is named under it")
def _(t):
    t.path("empty").mkdir()
    t.run("haptics", "sim", env={"PROPRIO_DATA_DIR": str(t.path("empty"))}, timeout=30).fails_cleanly(
        r"empty/haptics/band_2dof\.toml")


# --- 28: simulator switches -------------------------------------------------------------


@case("28 bench glove / bench vist --without an effect that does not exist: refused by name, nothing runs")
def _(t):
    t.run("bench", "glove", "--subjects", "1", "--without", "noise,gremlins", timeout=30).fails_cleanly(r"gremlins")
    t.run("bench", "vist", "--subjects", "1", "--without", "", timeout=30).fails_cleanly(r"without")
