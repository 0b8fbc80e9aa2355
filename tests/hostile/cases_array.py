"""Stretch sensor arrays (issue 30, docs/stretch-arrays.md): `array check` and
`array layout` against special files, broken and hostile TOML, layouts whose
strips cross twice, and outputs that must not be overwritten; `sim-array`,
`train array`, `bench array` and `stretch-board emulate --layout` against the
same and against bad numbers, damaged datasets and clashing writers; and
`record array` from the in-process emulated board: a recording read back,
a board that does not match, an unplug, Ctrl-C."""
import json
import math
import os
import re
import shutil
import signal
import struct
import subprocess
import time
import zlib

from hostile import case

STRIPS = '[[top_strip]]\nname = "1"\n[[bottom_strip]]\nname = "A"\n'
CELL = '[[cell]]\ntop = "1"\nbottom = "A"\n'


@case("30 array check on /dev/zero, a FIFO, a folder, a missing file: refused at once, named")
def _(t):
    t.run("array", "check", "/dev/zero", timeout=20).fails_cleanly(r"/dev/zero.*character device")
    fifo = t.fifo("layout.toml")
    t.run("array", "check", fifo, timeout=20).fails_cleanly(r"layout.toml.*FIFO")
    t.path("folder").mkdir()
    t.run("array", "check", t.path("folder"), timeout=20).fails_cleanly(r"folder")
    t.run("array", "check", "missing.toml", timeout=20).fails_cleanly(r"missing.toml")


@case("30 array check on broken TOML, binary bytes, a huge file: refused with the file")
def _(t):
    t.run("array", "check", t.write("broken.toml", "[[top_strip]\nname = \n")).fails_cleanly(r"broken.toml:\d+")
    t.run("array", "check", t.write("binary.toml", bytes(range(256)) * 16)).fails_cleanly(r"binary.toml")
    t.run("array", "check", t.write("huge.toml", "# " + "x" * (5 * 1024 * 1024) + "\n"), timeout=30).fails_cleanly(
        r"huge.toml.*(too large|bigger|MiB|bytes)")


@case("30 array check: strips crossing twice, an unknown strip, nan sizes, a self-crossing outline: refused, named")
def _(t):
    twice = STRIPS + CELL + '[[cell]]\nname = "again"\ntop = "1"\nbottom = "A"\n'
    t.run("array", "check", t.write("twice.toml", twice)).fails_cleanly(r"cross twice")
    t.run("array", "check", t.write("unknown.toml", STRIPS + '[[cell]]\ntop = "9"\nbottom = "A"\n')).fails_cleanly(
        r"unknown.toml:\d+.*no top strip named '9'")
    nan = STRIPS.replace('name = "1"\n', 'name = "1"\nwidth_m = nan\n') + CELL
    t.run("array", "check", t.write("nan.toml", nan)).fails_cleanly(r"nan.toml.*width_m")
    bow = STRIPS + CELL + 'outline_m = [0, 0, 0.004, 0.004, 0.004, 0, 0, 0.004]\n'
    t.run("array", "check", t.write("bow.toml", bow)).fails_cleanly(r"crosses itself")


@case("30 array layout --out over an existing file without --force: refused, the file unchanged")
def _(t):
    t.write("mine.toml", "name = \"mine\"\n")
    t.watch("mine.toml")
    t.run("array", "layout", "--out", "mine.toml").fails_cleanly(r"mine.toml.*exists")
    t.unchanged()
    t.path("dir").mkdir()
    t.run("array", "layout", "--out", t.path("dir")).fails_cleanly(r"dir")
    t.run("array", "layout", "--example", "nope").fails_cleanly(r"nope")


# --- sim-array, train array, bench array, record array, stretch-board emulate --layout ---------------------------

TINY = ["--train-minutes", "0.05", "--test-minutes", "0.05", "--no-redonned"]


def grid_layout(n: int, name: str) -> str:
    """An n x n strip grid crossing everywhere: n^2 cells, readable with M^I and M^II."""
    s = f'name = "{name}"\n'
    for layer, prefix in (("top_strip", "T"), ("bottom_strip", "B")):
        for i in range(n):
            s += f'[[{layer}]]\nname = "{prefix}{i}"\ncentre_m = {0.012 * i}\nwidth_m = 0.008\n'
    for i in range(n):
        for j in range(n):
            s += f'[[cell]]\ntop = "T{i}"\nbottom = "B{j}"\n'
    return s


def sim_dataset(t, name: str = "ds"):
    t.run("sim-array", "--out", name, *TINY, timeout=60).expect(rc=0)
    return t.path(name)


@case("30 sim-array --layout /dev/zero, a FIFO, broken TOML, a missing file: refused at once, named")
def _(t):
    t.run("sim-array", "--layout", "/dev/zero", "--out", "d", *TINY, timeout=20).fails_cleanly(r"/dev/zero.*character device")
    t.run("sim-array", "--layout", t.fifo("l.toml"), "--out", "d", *TINY, timeout=20).fails_cleanly(r"l.toml.*FIFO")
    t.run("sim-array", "--layout", t.write("broken.toml", "[[top_strip]\nname = \n"), "--out", "d", *TINY,
          timeout=20).fails_cleanly(r"broken.toml:\d+")
    t.run("sim-array", "--layout", "missing.toml", "--out", "d", *TINY, timeout=20).fails_cleanly(r"missing.toml")
    assert not t.path("d").exists() or not (t.path("d") / "meta.json").exists(), "a refused run left a dataset"


@case("30 sim-array: NaN, inf and negative numbers in options are refused, named")
def _(t):
    for option in ["--train-minutes", "--test-minutes", "--rate", "--train-sessions", "--threads"]:
        for v in ["nan", "inf", "-1"]:
            t.run("sim-array", "--out", "d", option, v, timeout=20).fails_cleanly(re.escape(option))


@case("30 sim-array --out a regular file, or a dataset another sim-array is writing: refused, nothing lost")
def _(t):
    t.write("regular", "precious\n")
    t.watch("regular")
    t.run("sim-array", "--out", "regular", *TINY, timeout=30).fails_cleanly(r"regular")
    t.run("sim-array", "--out", "regular", "--force", *TINY, timeout=30).fails_cleanly(r"regular")
    # A long run holds the dataset's lock; a second writer must not interleave with it.
    first = t.start("sim-array", "--out", "D", "--train-minutes", "5", "--test-minutes", "0.05", "--no-redonned",
                    "--threads", "1")
    try:
        deadline = time.monotonic() + 20
        while not t.path("D/.lock").exists() and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert first.poll() is None, f"the first sim-array ended early: {first.communicate()[1][-800:]!r}"
        t.run("sim-array", "--out", "D", "--force", *TINY, timeout=30).fails_cleanly(r"in use by another process")
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.communicate()


@case("30 sim-array --layout unreadable (no permission): refused, named")
def _(t):
    t.need(os.geteuid() != 0, "root reads files whatever their permissions")
    p = t.write("secret.toml", grid_layout(3, "g3"))
    p.chmod(0)
    t.run("sim-array", "--layout", p, "--out", "d", *TINY, timeout=20).fails_cleanly(r"secret.toml")


@case("30 train array: a missing folder, no meta.json, a bad --models, no python: refused before training, named")
def _(t):
    t.run("train", "array", "missing", "--out", "m", "--tiny", timeout=30).fails_cleanly(r"missing")
    t.path("empty").mkdir()
    t.run("train", "array", "empty", "--out", "m", "--tiny", timeout=30).fails_cleanly(r"empty.*meta.json")
    sim_dataset(t)
    t.run("train", "array", "ds", "--out", "m", "--models", "bogus", "--tiny", timeout=30).fails_cleanly(r"bogus")
    t.run("train", "array", "ds", "--out", "m", "--python", "/nonexistent", "--tiny", timeout=30).fails_cleanly(
        r"/nonexistent")
    assert not (t.path("m") / "lr" / "model.onnx").exists()


@case("30 train array on cells.npy cut short, holding NaN, or a symlink to /dev/zero: refused, named")
def _(t):
    src = sim_dataset(t)
    cells = (src / "cells.npy").read_bytes()
    for name in ["cut", "nan", "zero"]:
        shutil.copytree(src, t.path(name))
    t.write("cut/cells.npy", cells[: len(cells) // 2])
    header = struct.unpack_from("<H", cells, 8)[0]
    data = bytearray(cells)
    fmt = "<f" if b"'<f4'" in cells[10:10 + header] else "<d"
    struct.pack_into(fmt, data, 10 + header + 7 * struct.calcsize(fmt), float("nan"))
    t.write("nan/cells.npy", bytes(data))
    t.path("zero/cells.npy").unlink()
    t.path("zero/cells.npy").symlink_to("/dev/zero")
    t.run("train", "array", "cut", "--out", "m1", "--tiny", "--models", "lr", timeout=60).fails_cleanly(
        r"cells.npy.*(cut short|bytes)")
    t.run("train", "array", "nan", "--out", "m2", "--tiny", "--models", "lr", timeout=60).fails_cleanly(
        r"cells.npy.*(NaN|finite)")
    t.run("train", "array", "zero", "--out", "m3", "--tiny", "--models", "lr", timeout=60).fails_cleanly(
        r"cells.npy.*character device")


@case("30 bench array: a bad --cases, NaN or inf numbers: refused, named")
def _(t):
    t.run("bench", "array", "--cases", "bogus", timeout=20).fails_cleanly(r"--cases")
    for option in ["--max-stretch", "--seconds"]:
        for v in ["nan", "inf", "-1"]:
            t.run("bench", "array", option, v, timeout=20).fails_cleanly(re.escape(option))


@case("30 stretch-board emulate --layout: /dev/zero, a FIFO, broken TOML, more strips than the wire: refused, named")
def _(t):
    t.run("stretch-board", "emulate", "--layout", "/dev/zero", "--seconds", "1", timeout=20).fails_cleanly(
        r"/dev/zero.*character device")
    t.run("stretch-board", "emulate", "--layout", t.fifo("l.toml"), "--seconds", "1", timeout=20).fails_cleanly(
        r"l.toml.*FIFO")
    t.run("stretch-board", "emulate", "--layout", t.write("broken.toml", "[[cell]\n"), "--seconds", "1",
          timeout=20).fails_cleanly(r"broken.toml:\d+")
    wide = "".join(f'[[top_strip]]\nname = "t{i}"\n' for i in range(40)) + '[[bottom_strip]]\nname = "A"\n'
    wide += "".join(f'[[cell]]\ntop = "t{i}"\nbottom = "A"\n' for i in range(40))
    t.run("stretch-board", "emulate", "--layout", t.write("wide.toml", wide), "--seconds", "1",
          timeout=20).fails_cleanly(r"40 top.*1 to 32")


# --- record array ------------------------------------------------------------------------------------------------

REC_MAGIC = b"\x89PRP\r\n\x1a\n"


def read_recording(path):
    """(streams {id: (kind, name, meta)}, records [(stream id, time_ns, payload)]) per docs/recording-format.md."""
    data = path.read_bytes()
    assert data[:8] == REC_MAGIC, "not a Proprio recording"
    _major, _minor, pos = struct.unpack_from("<HHI", data, 8)
    streams, records, ended = {}, [], False
    while pos + 20 <= len(data):
        length, rtype, _, sid, t_ns = struct.unpack_from("<IBBHq", data, pos)
        end = pos + 16 + length
        assert end + 4 <= len(data), f"record at byte {pos} cut short"
        assert zlib.crc32(data[pos:end]) == struct.unpack_from("<I", data, end)[0], f"bad CRC at byte {pos}"
        payload = data[pos + 16:end]
        if rtype == 1:
            kind, _, n = struct.unpack_from("<BBH", payload, 0)
            (m,) = struct.unpack_from("<I", payload, 4 + n)
            streams[sid] = (kind, payload[4:4 + n].decode(), payload[8 + n:8 + n + m].decode())
        elif rtype == 2:
            records.append((sid, t_ns, payload))
        elif rtype == 3:
            ended = True
            break
        pos = end + 4
    return streams, records, ended


def check_array_recording(t, path, cells: int, rows: int, frames_at_least: int):
    """The streams exist; every cell is finite, and solved cells read C/C0 of a sleeve stretched at most 1.25x
    (the emulated one): the rest calibration removed each row's 1-5 pF stray capacitance, several times a cell's."""
    t.run("replay", path, timeout=30).expect(rc=0)
    streams, records, ended = read_recording(path)
    names = {v[1]: (k, v) for k, v in streams.items()}
    for want in ["array/measurements", "array/cells", "events"]:
        assert want in names, f"no stream {want} in {sorted(names)}"
    cell_id, (_, _, cell_meta) = names["array/cells"]
    meas_id = names["array/measurements"][0]
    meta = json.loads(cell_meta)
    rest_pf = meta["rest_pf"]
    assert len(rest_pf) == cells and len(meta["row_parasitic_pf"]) == rows, meta.keys()
    frames = [p for sid, _, p in records if sid == cell_id]
    assert len(frames) >= frames_at_least, f"{len(frames)} cell frames"
    solved = 0
    for p in frames:
        (n,) = struct.unpack_from("<I", p, 0)
        assert n == cells, f"a frame of {n} cells"
        for c, v in enumerate(struct.unpack_from(f"<{n}d", p, 4)):
            assert math.isfinite(v), "a cell is not finite"
            if v != 0.0:
                solved += 1
                ratio = v * 1e12 / rest_pf[c]
                assert 0.95 < ratio < 1.3, f"cell {c} reads C/C0 = {ratio:.3f}"
    assert solved >= 0.9 * cells * len(frames), f"only {solved} of {cells * len(frames)} cells solved"
    for sid, _, p in records:
        if sid == meas_id:
            assert len(p) % 16 == 0 and len(p) > 0
            assert all(struct.unpack_from("<H", p, i)[0] < rows for i in range(0, len(p), 16))
    events = " ".join(p.decode() for sid, _, p in records if sid == names["events"][0])
    return ended, events


@case("30 record array --emulate: 3 s from the in-process board, replayed: the streams, finite calibrated cells")
def _(t):
    t.write("g3.toml", grid_layout(3, "g3"))
    r = t.run("record", "array", "--layout", "g3.toml", "--out", "r.prec", "--emulate", "--seconds", "3",
              "--rest-seconds", "1", "--interval", "0.5", timeout=30).expect(rc=0, out=r"rest calibration done")
    assert re.search(r"recording\s+streaming\s+\d+ frames", r.out), r.describe()
    ended, events = check_array_recording(t, t.path("r.prec"), cells=9, rows=15, frames_at_least=60)
    assert ended and "calibration done" in events and "recording end" in events, events


@case("30 record array: no board, a board that does not match, --out over its layout or an existing file: refused")
def _(t):
    t.write("g3.toml", grid_layout(3, "g3"))
    t.write("g2.toml", grid_layout(2, "g2"))
    t.write("old.prec", "keep me")
    t.watch("g3.toml", "old.prec")
    # No stretch board on a CI machine (or none with these USB IDs).
    t.run("record", "array", "--layout", "g3.toml", "--out", "r.prec", "--vid", "0001", "--pid", "0001",
          timeout=20).fails_cleanly(r"no stretch board found")
    t.run("record", "array", "--layout", "g3.toml", "--out", "r.prec", "--path", "/dev/null",
          timeout=20).fails_cleanly(r"/dev/null")
    t.run("record", "array", "--layout", "g3.toml", "--out", "r.prec", "--emulate", "--emulate-layout", "g2.toml",
          timeout=20).fails_cleanly(r"does not match.*2 x 2 strips.*'g3'.*3 x 3 strips")
    assert not t.path("r.prec").exists(), "a failed start left a recording"
    t.run("record", "array", "--layout", "g3.toml", "--out", "g3.toml", "--emulate",
          timeout=20).fails_cleanly(r"g3.toml.*input")
    t.run("record", "array", "--layout", "g3.toml", "--out", "old.prec", "--emulate",
          timeout=20).fails_cleanly(r"old.prec.*exists")
    t.path("dir").mkdir()
    t.run("record", "array", "--layout", "g3.toml", "--out", "dir", "--emulate", timeout=20).fails_cleanly(r"dir")
    t.run("record", "array", "--layout", "g3.toml", "--out", t.fifo("pipe.prec"), "--force", "--emulate",
          timeout=20).fails_cleanly(r"pipe.prec.*not a regular file")
    t.run("record", "array", "--layout", "/dev/zero", "--out", "r.prec", "--emulate",
          timeout=20).fails_cleanly(r"/dev/zero")
    for option, v in [("--rest-seconds", "nan"), ("--seconds", "inf"), ("--rest-seconds", "-1"),
                      ("--disconnect-timeout", "nan")]:
        t.run("record", "array", "--layout", "g3.toml", "--out", "r.prec", "--emulate", option, v,
              timeout=20).fails_cleanly(re.escape(option))
    t.run("record", "array", "--layout", "g3.toml", "--out", "r.prec", "--seconds", "2", "--rest-seconds", "3",
          "--emulate", timeout=20).fails_cleanly(r"--seconds.*rest")
    t.run("record", "array", "--layout", "g3.toml", "--out", "r.prec", "--unplug", "1:1",
          timeout=20).fails_cleanly(r"only to --emulate")


@case("30 record array --emulate: the board unplugged for good ends it non-zero; the file reads up to then")
def _(t):
    t.write("g3.toml", grid_layout(3, "g3"))
    r = t.run("record", "array", "--layout", "g3.toml", "--out", "u.prec", "--emulate", "--rest-seconds", "1",
              "--unplug", "2:60", "--disconnect-timeout", "0.5", "--seconds", "20", timeout=30)
    r.fails_cleanly(r"unplugged and did not come back.*recording up to then is in u.prec")
    assert r.seconds < 10, r.describe()
    ended, events = check_array_recording(t, t.path("u.prec"), cells=9, rows=15, frames_at_least=30)
    assert "board unplugged" in events and "recording ended" in events, events


@case("30 record array --emulate: Ctrl-C ends it cleanly with a readable file")
def _(t):
    t.write("g3.toml", grid_layout(3, "g3"))
    p = t.start("record", "array", "--layout", "g3.toml", "--out", "c.prec", "--emulate", "--rest-seconds", "0.5")
    try:
        out, err = p.communicate(timeout=2.5)
        raise AssertionError(f"ended before Ctrl-C: {p.returncode} {err[-800:]!r}")
    except subprocess.TimeoutExpired:
        pass
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=15)
    assert p.returncode == 0, (p.returncode, err[-800:])
    ended, events = check_array_recording(t, t.path("c.prec"), cells=9, rows=15, frames_at_least=30)
    assert ended and '"interrupted":true' in events.replace(" ", ""), events


@case("30 record array --from-file: a capture of the layout's board is recorded; another board's, /dev/zero: refused")
def _(t):
    t.write("g3.toml", grid_layout(3, "g3"))
    t.run("stretch-board", "emulate", "--layout", "g3.toml", "--out", "g3.bin", "--seconds", "3", "--unplug", "2:0.3",
          timeout=30).expect(rc=0)
    t.run("stretch-board", "emulate", "--out", "glove.bin", "--seconds", "1", timeout=30).expect(rc=0)
    t.watch("g3.bin")
    t.run("record", "array", "--layout", "g3.toml", "--from-file", "g3.bin", "--out", "f.prec", "--rest-seconds", "1",
          timeout=30).expect(rc=0, out=r"board restarted.*wrote f.prec")
    streams, records, ended = read_recording(t.path("f.prec"))
    assert ended and {"array/cells", "array/measurements", "events"} <= {v[1] for v in streams.values()}, streams
    t.run("record", "array", "--layout", "g3.toml", "--from-file", "glove.bin", "--out", "g.prec",
          timeout=30).fails_cleanly(r"glove.bin.*13 x 14 strips \(pairs only\).*3 x 3 strips with single strips")
    assert not t.path("g.prec").exists()
    t.run("record", "array", "--layout", "g3.toml", "--from-file", "/dev/zero", "--out", "z.prec",
          timeout=30).fails_cleanly(r"/dev/zero.*character device")
    t.run("record", "array", "--layout", "g3.toml", "--from-file", "g3.bin", "--out", "g3.bin", "--force",
          timeout=30).fails_cleanly(r"g3.bin.*input")
    t.run("record", "array", "--layout", "g3.toml", "--from-file", "g3.bin", "--emulate", "--out", "e.prec",
          timeout=30).fails_cleanly(r"--emulate and --from-file")
