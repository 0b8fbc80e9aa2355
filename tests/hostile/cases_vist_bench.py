"""`proprio bench vist`: every case runs in both modes, and a case that cannot
be scored says so and fails the command; it is never reported as a number."""
import json
from pathlib import Path

from hostile import case


@case("bench vist --mode images: every challenge runs (rendered), with scored samples")
def _(t):
    # 12 s: the occlusion (8-10 s), out-of-view (9-12 s) and unplug (10-11 s) windows all fall inside.
    r = t.run("bench", "vist", "--mode", "images", "--suite", "challenges", "--subjects", "1",
              "--challenge-minutes", "0.2", "--threads", "2", "--json", timeout=600)
    r.expect(rc=0)
    cases = {c["name"]: c for c in json.loads(r.out)["cases"]}
    for name in ("occlude_half", "out_of_view", "distractors", "dropped_frames", "imu_unplug"):
        c = cases[name]
        assert c["ran"] is True and c["keypoints"]["samples"] > 0, f"{name}: {c}"
        assert "error" not in c, f"{name}: {c}"


@case("bench vist: a camera that never sees the hand scores nothing; every case says it did not run, exit 1, no figures")
def _(t):
    glove = (Path(__file__).resolve().parents[2] / "config" / "vist_glove.toml").read_text()
    assert "left_camera_tilt_down_deg = 25.0" in glove
    looking_up = t.write("ceiling_camera.toml", glove.replace("left_camera_tilt_down_deg = 25.0",
                                                               "left_camera_tilt_down_deg = -90.0"))
    r = t.run("bench", "vist", "--suite", "challenges", "--subjects", "1", "--glove", looking_up,
              "--challenge-minutes", "0.1", "--threads", "2", "--json", timeout=300)
    r.expect(rc=1, err=r"occlude_half.*nothing was scored")
    cases = {c["name"]: c for c in json.loads(r.out)["cases"]}
    assert len(cases) == 5, cases
    for name, c in cases.items():
        assert c["ran"] is False, f"{name}: {c}"
        assert "keypoints" not in c and "mean_mm" not in json.dumps(c), f"{name} reports figures: {c}"
        assert "warm-up" in c["error"], c
    t.run("bench", "vist", "--suite", "challenges", "--subjects", "1", "--glove", looking_up,
          "--challenge-minutes", "0.1", "--threads", "2", timeout=300).expect(
        rc=1, out=r"occlude_half\s+did not run: nothing was scored")


@case("bench vist --without: an unknown simulator effect is refused by name before anything runs")
def _(t):
    r = t.run("bench", "vist", "--suite", "free", "--subjects", "1", "--without", "wobble,gremlins", timeout=60)
    r.expect(rc={1, 2}, err=r"gremlins")
    assert "VIST on simulated subjects" not in r.out, r.out
