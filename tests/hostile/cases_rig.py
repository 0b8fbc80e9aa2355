"""The modular rig device (issue 31, docs/rig-device.md): `rig example`, `rig plan`,
`rig emulate`, `rig live` and `bench rig` against special files, broken and hostile
glTF (cycles, NaN keyframes, non-unit scale, no skin, no samples), hostile plans
(truncated, NaN quaternions, nodes out of range, another character's plan) and
kits, bad numbers, and outputs that must not be overwritten or shared."""
import json
import re
import time

from hostile import case

MIN_GLTF = {
    "asset": {"version": "2.0"},
    "scenes": [{"nodes": [0, 2]}],
    "scene": 0,
}


def example(t, name="humanoid"):
    t.run("rig", "example", name, "--out", f"{name}.gltf", timeout=60).expect(rc=0)
    return t.path(f"{name}.gltf")


def plan(t, character, out="plan"):
    t.run("rig", "plan", character, "--out", out, timeout=120).expect(rc=0)
    return t.path(out) / "plan.json"


@case("31 rig plan on /dev/zero, a FIFO, a folder, a missing file, binary bytes: refused at once, named")
def _(t):
    t.run("rig", "plan", "/dev/zero", "--out", "p", timeout=20).fails_cleanly(r"/dev/zero")
    t.run("rig", "plan", t.fifo("c.gltf"), "--out", "p", timeout=20).fails_cleanly(r"c.gltf.*FIFO")
    t.path("folder.gltf").mkdir()
    t.run("rig", "plan", t.path("folder.gltf"), "--out", "p", timeout=20).fails_cleanly(r"folder.gltf")
    t.run("rig", "plan", "missing.gltf", "--out", "p", timeout=20).fails_cleanly(r"missing.gltf")
    t.run("rig", "plan", t.write("bytes.gltf", bytes(range(256)) * 8), "--out", "p", timeout=20).fails_cleanly(
        r"bytes.gltf")
    assert not (t.path("p") / "plan.json").exists(), "a refused plan left a plan.json"


@case("31 rig plan on glTF that is not a character: no skin, no samples, a node cycle, non-unit scale")
def _(t):
    src = json.loads(example(t).read_text())
    # No skin at all.
    no_skin = json.loads(json.dumps(src))
    no_skin.pop("skins", None)
    for n in no_skin.get("nodes", []):
        n.pop("skin", None)
    t.run("rig", "plan", t.write("noskin.gltf", json.dumps(no_skin)), "--out", "p1", timeout=30).fails_cleanly(
        r"noskin.gltf.*skin")
    # No animation: no sample poses to plan from.
    no_anim = json.loads(json.dumps(src))
    no_anim.pop("animations", None)
    t.run("rig", "plan", t.write("noanim.gltf", json.dumps(no_anim)), "--out", "p2", timeout=30).fails_cleanly(
        r"noanim.gltf.*sample poses")
    # A child that lists its own parent as a child: a cycle.
    cyc = json.loads(json.dumps(src))
    joints = cyc["skins"][0]["joints"]
    a, b = joints[0], joints[1]
    cyc["nodes"][b].setdefault("children", []).append(a)
    t.run("rig", "plan", t.write("cycle.gltf", json.dumps(cyc)), "--out", "p3", timeout=30).fails_cleanly(
        r"cycle.gltf.*(cycle|parent|hierarchy|child)")
    # A scaled joint.
    scaled = json.loads(json.dumps(src))
    scaled["nodes"][joints[2]]["scale"] = [2.0, 2.0, 2.0]
    t.run("rig", "plan", t.write("scaled.gltf", json.dumps(scaled)), "--out", "p4", timeout=30).fails_cleanly(
        r"scaled.gltf.*scale")
    assert not any((t.path(p) / "plan.json").exists() for p in ["p1", "p2", "p3", "p4"]), "a refused plan was written"


@case("31 rig plan --out over an existing plan without --force, or a folder another rig plan holds: refused, unchanged")
def _(t):
    c = example(t)
    plan(t, c, "mine")
    t.watch(*[f"mine/{f}" for f in ["plan.json", "assembly.txt", "assembly.svg", "error_curve.svg"]])
    t.run("rig", "plan", c, "--out", "mine", timeout=60).fails_cleanly(r"plan.json exists.*--force")
    t.unchanged()
    t.write("afile", "precious\n")
    t.watch("afile")
    t.run("rig", "plan", c, "--out", "afile", timeout=60).fails_cleanly(r"afile.*not a folder")
    t.unchanged()
    t.run("rig", "example", "humanoid", "--out", c, timeout=60).fails_cleanly(r"exists.*--force")
    t.run("rig", "example", "dragon", "--out", "x.gltf", timeout=20).fails_cleanly(r"dragon")


@case("31 rig plan --kit: broken TOML, NaN lengths, absurd counts, /dev/zero: refused with the file")
def _(t):
    c = example(t)
    t.run("rig", "plan", c, "--out", "p", "--kit", t.write("broken.toml", "[joint\nname = \n"),
          timeout=30).fails_cleanly(r"broken.toml")
    t.run("rig", "plan", c, "--out", "p", "--kit", t.write("nan.toml", "[joint]\nlength_in_m = nan\n"),
          timeout=30).fails_cleanly(r"nan.toml.*length_in_m")
    t.run("rig", "plan", c, "--out", "p", "--kit", t.write("many.toml", "[joint]\ncount = 100000000\n"),
          timeout=30).fails_cleanly(r"many.toml.*count")
    t.run("rig", "plan", c, "--out", "p", "--kit", "/dev/zero", timeout=20).fails_cleanly(r"/dev/zero")
    for v in ["nan", "inf", "-1", "0"]:
        t.run("rig", "plan", c, "--out", "p", "--joints", v, timeout=20).fails_cleanly(r"--joints")


@case("31 rig emulate / rig live with a hostile plan: truncated, NaN quaternion, node out of range, another character's")
def _(t):
    human = example(t, "humanoid")
    quad = example(t, "quadruped")
    good = plan(t, human)
    text = good.read_text()
    t.run("rig", "emulate", "--plan", t.write("trunc.json", text[: len(text) // 2]), "--character", human,
          "--seconds", "1", timeout=30).fails_cleanly(r"trunc.json")
    doc = json.loads(text)
    doc["modules"][0]["q_parent_inlet"] = [float("nan"), 0, 0, 0]
    t.run("rig", "emulate", "--plan", t.write("nan.json", json.dumps(doc)), "--character", human, "--seconds", "1",
          timeout=30).fails_cleanly(r"nan.json")
    doc = json.loads(text)
    doc["modules"][-1]["rig_node"] = 100000
    t.run("rig", "emulate", "--plan", t.write("range.json", json.dumps(doc)), "--character", human, "--seconds", "1",
          timeout=30).fails_cleanly(r"range.json.*(module|node)")
    t.run("rig", "live", "--plan", good, "--character", quad, "--seconds", "1", timeout=60).fails_cleanly(
        r"(made for the character 'humanoid'|module|node)")
    t.run("rig", "emulate", "--plan", "/dev/zero", "--character", human, timeout=20).fails_cleanly(r"/dev/zero")
    t.run("rig", "emulate", "--plan", t.fifo("p.json"), "--character", human, timeout=20).fails_cleanly(r"FIFO")


@case("31 rig emulate / rig live: NaN, inf and out-of-range fault and pace numbers are refused, named")
def _(t):
    human = example(t)
    good = plan(t, human)
    for option in ["--loss", "--corrupt", "--power-loss-every", "--skew-ppm", "--seconds-per-pose", "--seconds"]:
        for v in ["nan", "inf", "-1"]:
            t.run("rig", "emulate", "--plan", good, "--character", human, option, v, timeout=20).fails_cleanly(
                re.escape(option))
    t.run("rig", "emulate", "--plan", good, "--character", human, "--loss", "0.9", timeout=20).fails_cleanly(r"--loss")
    t.run("rig", "live", "--plan", good, "--character", human, "--device", "bluetooth", timeout=20).fails_cleanly(
        r"--device")


@case("31 rig emulate under heavy faults: it runs, the host's topology is shown, nothing crashes")
def _(t):
    human = example(t)
    good = plan(t, human)
    r = t.run("rig", "emulate", "--plan", good, "--character", human, "--seconds", "3", "--loss", "0.3",
              "--corrupt", "0.2", "--power-loss-every", "0.5", "--skew-ppm", "10000", timeout=60).expect(rc=0)
    assert re.search(r"host: \d+ components attached", r.out), r.describe()
    assert re.search(r"power losses", r.out), r.describe()


@case("31 rig live --device usb with no base plugged in: says so, exits non-zero, no hang")
def _(t):
    human = example(t)
    good = plan(t, human)
    t.run("rig", "live", "--plan", good, "--character", human, "--device", "usb", "--seconds", "2", "--size",
          "160x90", "--out", "f", timeout=60, max_mb=8192).fails_cleanly(r"(no joint of the plan was ever live|no .*device|hid)")


@case("31 rig live --record over an existing file: refused, the file unchanged")
def _(t):
    human = example(t)
    good = plan(t, human)
    t.write("keep.prec", "precious\n")
    t.watch("keep.prec")
    t.run("rig", "live", "--plan", good, "--character", human, "--seconds", "1", "--record", "keep.prec",
          timeout=60, max_mb=8192).fails_cleanly(r"keep.prec.*exists")
    t.unchanged()


@case("31 bench rig: an unknown case is refused; a quick run prints JSON with every case run")
def _(t):
    t.run("bench", "rig", "--cases", "everything", timeout=20).fails_cleanly(r"--cases")
    r = t.run("bench", "rig", "--quick", "--json", "--cases", "joints", "posing", timeout=120).expect(rc=0)
    doc = json.loads(r.out)
    assert doc["joints"]["ran"] and doc["posing"]["ran"], r.describe()
    assert "bus" not in doc and "reduction" not in doc, "cases that were not asked for appear as run"
