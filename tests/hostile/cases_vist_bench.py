"""`proprio bench vist`: a case that cannot run says so and fails the command;
it is never reported as a number."""
import json

from hostile import case


@case("bench vist --mode images: the challenges that hide markers by identity say they did not run, exit 1, no figures")
def _(t):
    r = t.run("bench", "vist", "--mode", "images", "--suite", "challenges", "--subjects", "1",
              "--challenge-minutes", "0.1", "--threads", "2", "--json", timeout=300)
    r.expect(rc=1, err=r"occlude_half.*only in the detections mode")
    cases = {c["name"]: c for c in json.loads(r.out)["cases"]}
    for name in ("occlude_half", "out_of_view", "imu_unplug"):
        c = cases[name]
        assert c["ran"] is False, f"{name}: {c}"
        assert "keypoints" not in c and "mean_mm" not in json.dumps(c), f"{name} reports figures: {c}"
        assert "only in the detections mode" in c["error"], c
    for name in ("distractors", "dropped_frames"):
        assert cases[name]["ran"] is True and cases[name]["keypoints"]["samples"] > 0, cases[name]
    t.run("bench", "vist", "--mode", "images", "--suite", "challenges", "--subjects", "1",
          "--challenge-minutes", "0.1", "--threads", "2", timeout=300).expect(
        rc=1, out=r"occlude_half\s+did not run: .*only in the detections mode")
