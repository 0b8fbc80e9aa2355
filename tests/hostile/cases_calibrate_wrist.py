"""`proprio calibrate wrist` against bad option values, output paths that must
not be written, a runtime without what it needs, Proprio's own layer in the
way, Ctrl-C, and the mock OpenXR runtime's devices (tests/openxr/mock_runtime:
two simple controllers, VIVE trackers with roles left_wrist/right_wrist and,
with PROPRIO_MOCK_RUNTIME_HAND_TRACKING=moving, a moving native hand that
every device follows)."""
import os
import signal
import time
from pathlib import Path

from hostile import case

LAYER = "XR_APILAYER_PROPRIO_hand_tracking"
LAVAPIPE_ICD = Path("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json")
BASE = ["calibrate", "wrist", "--hand", "right", "--device", "tracker", "--non-interactive", "--out", "w.toml"]
# The mock's hand never stops: accept its motion where a run must succeed.
MOVING_OK = ["--max-angular-speed-deg-s", "360", "--max-position-spread-m", "0.5", "--max-rotation-spread-deg", "90"]
# The mock's true right tracker-to-wrist offset (mock_motion.hpp, kTrackerToWristRight), as the CLI prints it.
RIGHT_TRACKER_TRUTH = (r"position \[0\.0200, -0\.0350, -?0\.0000\] m, rotation \[-?0\.00, -90\.00, -?0\.00\] deg")


def mock_env(t, **extra):
    t.need(bool(t.opts.mock_runtime_json) and Path(t.opts.mock_runtime_json).exists(),
           "no mock OpenXR runtime manifest (--mock-runtime-json)")
    env = {"XR_RUNTIME_JSON": str(Path(t.opts.mock_runtime_json).resolve()),
           "XDG_CONFIG_HOME": str(t.path("cfg"))}
    env.update(extra)
    return env


# --- every option's bad values are refused before any OpenXR work ---------------------

BAD_VALUES = [
    ("--hand", ["middle", "", "LEFT"]),
    ("--device", ["glove", ""]),
    ("--role", ["left_wirst", "", "waist\n"]),
    ("--reference", ["hand", "runtime_hand", ""]),
    ("--seconds", ["nan", "inf", "0", "0.4", "31", "-2", "2s"]),
    ("--timeout", ["nan", "-inf", "0", "1e9", "10min"]),
    ("--wrist-below-device-m", ["nan", "0.5", "-1", "3cm"]),
    ("--wrist-behind-grip-m", ["nan", "-0.01", "1", "inf"]),
    ("--max-angular-speed-deg-s", ["nan", "inf", "0", "1000", "-5"]),
    ("--max-position-spread-m", ["nan", "0", "1", "-0.01"]),
    ("--max-rotation-spread-deg", ["nan", "0", "180", "inf"]),
    ("--session", ["bogus", "", "Vulkan"]),
]


@case("calibrate wrist: every option's bad values are refused with the option named, nothing written")
def _(t):
    for option, values in BAD_VALUES:
        for v in values:
            args = [a for a in BASE]
            if option in args:
                i = args.index(option)
                args[i + 1] = v
            else:
                args += [option, v]
            r = t.run(*args, timeout=20)
            r.fails_cleanly(r"--" + option.lstrip("-").split("-")[0])
            assert not t.path("w.toml").exists(), f"{option} {v!r} wrote a file\n" + r.describe()


@case("calibrate wrist: --hand and --device are required; --role only with a tracker; --timeout >= --seconds")
def _(t):
    t.run("calibrate", "wrist", "--device", "tracker", timeout=20).fails_cleanly(r"--hand")
    t.run("calibrate", "wrist", "--hand", "left", timeout=20).fails_cleanly(r"--device")
    t.run("calibrate", "wrist", "--hand", "left", "--device", "controller", "--role", "left_wrist",
          timeout=20).fails_cleanly(r"--role applies only to --device tracker")
    t.run(*BASE, "--seconds", "5", "--timeout", "4", timeout=20).fails_cleanly(
        r"--timeout \(4 s\) must be at least --seconds \(5 s\)")
    assert not t.path("w.toml").exists()


@case("calibrate wrist: an --out that is a folder, a FIFO or an existing calibration is refused up front")
def _(t):
    t.path("adir").mkdir()
    t.run(*BASE[:-1], "adir", timeout=20).fails_cleanly(r"adir.*(folder|director)")
    fifo = t.fifo("pipe.toml")
    t.run(*BASE[:-1], str(fifo), "--force", timeout=20).fails_cleanly(r"pipe\.toml.*not a regular file")
    t.write("w.toml", "[wrist]\nposition_m = [0.0, 0.0, 0.0]\nrotation_deg = [0.0, 0.0, 0.0]\n")
    t.watch("w.toml")
    # Refused before the runtime is touched: there is none here.
    t.run(*BASE, timeout=20).fails_cleanly(r"w\.toml' exists; pass --force")
    t.write("afile", "x")
    t.run(*BASE[:-1], "afile/sub/w.toml", timeout=20).fails_cleanly(r"cannot create the folder")


@case("calibrate wrist: no OpenXR runtime at all is a clean error")
def _(t):
    r = t.run(*BASE, env={"XR_RUNTIME_JSON": str(t.path("missing.json"))}, timeout=30)
    r.fails_cleanly(r"runtime|OpenXR|loader")
    assert not t.path("w.toml").exists()


# --- on the mock runtime -----------------------------------------------------------------


@case("calibrate wrist --reference runtime-hand on the mock: the true offset, in the per-user file, with the config lines")
def _(t):
    env = mock_env(t, PROPRIO_MOCK_RUNTIME_HAND_TRACKING="moving")
    args = ["calibrate", "wrist", "--hand", "right", "--device", "tracker", "--reference", "runtime-hand",
            "--non-interactive", *MOVING_OK]
    r = t.run(*args, env=env, timeout=60)
    r.expect(rc=0, out=RIGHT_TRACKER_TRUTH)
    r.expect(out=r"Assumed:\s+nothing")
    out = t.path("cfg") / "proprio" / "wrist" / "right_tracker.toml"
    assert out.exists(), "no file at the per-user default path\n" + r.describe()
    r.expect(out=r'wrist = "tracker"\s+wrist_calibration = "' + str(out) + r'"\s+tracker_role_right = "right_wrist"')
    t.watch(out)
    t.run(*args, env=env, timeout=60).fails_cleanly(r"right_tracker\.toml' exists; pass --force")
    t.unchanged()
    t._hashes.clear()
    t.run(*args, "--force", env=env, timeout=60).expect(rc=0, out=r"Wrote .*right_tracker\.toml")


@case("calibrate wrist: Proprio's layer, enabled explicitly or installed implicitly, is kept out of the measurement")
def _(t):
    t.need(bool(t.opts.layer_dir) and Path(t.opts.layer_dir).is_dir(), "no built layer (--layer-dir)")
    config = t.write("layer.toml", '[[source]]\ntype = "sim"\nhands = ["right"]\nspace = "view"\n')
    args = ["calibrate", "wrist", "--hand", "right", "--device", "tracker", "--reference", "runtime-hand",
            "--non-interactive", *MOVING_OK, "--out", "x.toml"]
    explicit = mock_env(t, PROPRIO_MOCK_RUNTIME_HAND_TRACKING="moving", PROPRIO_LAYER_CONFIG=str(config),
                        XR_API_LAYER_PATH=str(Path(t.opts.layer_dir).resolve()), XR_ENABLE_API_LAYERS=LAYER)
    t.run(*args, env=explicit, timeout=60).expect(rc=0, out=RIGHT_TRACKER_TRUTH)
    data = t.path("data")
    implicit_dir = data / "openxr" / "1" / "api_layers" / "implicit.d"
    implicit_dir.mkdir(parents=True)
    (implicit_dir / "XrApiLayer_proprio_hand_tracking.json").write_bytes(
        (Path(t.opts.layer_dir) / "XrApiLayer_proprio_hand_tracking.json").read_bytes())
    implicit = mock_env(t, PROPRIO_MOCK_RUNTIME_HAND_TRACKING="moving", PROPRIO_LAYER_CONFIG=str(config),
                        XDG_DATA_HOME=str(data))
    t.run(*args, "--force", env=implicit, timeout=60).expect(rc=0, out=RIGHT_TRACKER_TRUTH)


@case("calibrate wrist --reference runtime-hand without the runtime's own hand tracking: says so, writes nothing")
def _(t):
    r = t.run(*BASE, "--reference", "runtime-hand", env=mock_env(t), timeout=60)
    r.fails_cleanly(r"does not offer XR_EXT_hand_tracking itself.*--reference pose")
    assert not t.path("w.toml").exists()


@case("calibrate wrist: a device that never holds still is refused after --timeout, with the reason, nothing written")
def _(t):
    r = t.run(*BASE, "--timeout", "2.5", env=mock_env(t), timeout=60)
    r.fails_cleanly(r"not held still for 2 s within the 2\.5 s timeout.*turning at")
    r.expect(out=r"moved: turning at [\d.]+ deg/s \(limit 10\.0\); hold still")
    assert not t.path("w.toml").exists()


@case("calibrate wrist: no tracker with the role connected, and a controller that never shows up")
def _(t):
    r = t.run(*BASE, env=mock_env(t, PROPRIO_MOCK_RUNTIME_TRACKERS="0"), timeout=60)
    r.fails_cleanly(r"no VIVE tracker with the role right_wrist is connected \(connected trackers' roles: none\)")
    r = t.run("calibrate", "wrist", "--hand", "left", "--device", "controller", "--non-interactive", "--timeout", "2",
              "--out", "w.toml", env=mock_env(t, PROPRIO_MOCK_RUNTIME_CONTROLLERS="0"), timeout=60)
    r.fails_cleanly(r"left controller \(/user/hand/left\) never became tracked within the 2 s timeout")
    assert not t.path("w.toml").exists()


@case("calibrate wrist: Ctrl-C during the countdown stops cleanly, nothing written")
def _(t):
    p = t.start(*BASE[:-3], "--out", "w.toml", env=mock_env(t))
    time.sleep(2.0)
    os.kill(p.pid, signal.SIGINT)
    try:
        out, err = p.communicate(timeout=20)
    except Exception:
        p.kill()
        raise
    assert p.returncode == 1, f"exit {p.returncode}\nstdout: {out!r}\nstderr: {err!r}"
    assert b"Get into the pose" in out, out
    assert b"stopped" in err, err
    assert not t.path("w.toml").exists()


@case("calibrate wrist on a Monado-like runtime: falls back to Vulkan, builds its actions again, still measures")
def _(t):
    t.need(LAVAPIPE_ICD.exists(), f"no lavapipe Vulkan driver ({LAVAPIPE_ICD})")
    env = mock_env(t, PROPRIO_MOCK_RUNTIME_HAND_TRACKING="moving", PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS="1")
    r = t.run("calibrate", "wrist", "--hand", "right", "--device", "tracker", "--reference", "runtime-hand",
              "--non-interactive", *MOVING_OK, "--out", "w.toml", env=env, timeout=120)
    r.expect(rc=0, out=r"refuses frames in headless sessions.*Session: Vulkan graphics binding")
    r.expect(out=RIGHT_TRACKER_TRUTH)
