"""Hostile recordings (issue 23): commands that write over the file they read,
damaged bytes mid-file, a bad length field, wall-clock time stamps from a foreign
writer, ANSI escapes in stream names, special files, and replay memory."""
import os
import struct
import zlib

from hostile import case

MAGIC = b"\x89PRP\r\n\x1a\n"
IMU, HAND_POSE = 1, 4
REALTIME_NS = 1_700_000_000_000_000_000  # a CLOCK_REALTIME stamp (2023) in a CLOCK_MONOTONIC file


def records(data: bytes):
    """(offset, type, stream, time_ns, payload_len) of every record, per docs/recording-format.md."""
    assert data[:8] == MAGIC
    pos = struct.unpack_from("<I", data, 12)[0]
    while pos + 20 <= len(data):
        length, rtype, _, stream, t = struct.unpack_from("<IBBHq", data, pos)
        yield pos, rtype, stream, t, length
        pos += 20 + length


def stream_kinds(data: bytes) -> dict:
    kinds = {}
    for pos, rtype, stream, _, _ in records(data):
        if rtype == 1:
            kinds[stream] = data[pos + 16]
    return kinds


def restamp(data: bytearray, pos: int, t: int) -> None:
    """Sets a record's time and rewrites its CRC, as a foreign writer would."""
    length = struct.unpack_from("<I", data, pos)[0]
    struct.pack_into("<q", data, pos + 8, t)
    struct.pack_into("<I", data, pos + 16 + length, zlib.crc32(bytes(data[pos:pos + 16 + length])))


def nth_record_of_kind(data: bytes, kind: int, n: int) -> int:
    kinds = stream_kinds(data)
    hits = [pos for pos, rtype, stream, _, _ in records(data) if rtype == 2 and kinds.get(stream) == kind]
    return hits[min(n, len(hits) - 1)]


def sim_hand(t, name="a.prec", seconds="3"):
    t.run("sim-hand", "--seconds", seconds, "--out", name).expect(rc=0)
    return t.path(name)


def sim_vist(t, name="s.prec", seconds="8"):
    t.run("sim-vist", "--seconds", seconds, "--out", name, timeout=120).expect(rc=0)
    return t.path(name)


# --- 23.3: no command writes over a file it reads -------------------------------------------


@case("23.3 track vist --session X --out X --force refuses and keeps the input")
def _(t):
    sim_vist(t)
    t.watch("s.prec")
    t.run("track", "vist", "--session", "s.prec", "--out", "s.prec", "--force", timeout=120).fails_cleanly(
        r"refusing to write.*s\.prec.*input of this command")
    t.unchanged()


@case("23.3 track vist refuses its input through ./X and through a symlink")
def _(t):
    sim_vist(t)
    os.symlink("s.prec", t.path("link.prec"))
    t.watch("s.prec")
    for out in ("./s.prec", "link.prec"):
        t.run("track", "vist", "--session", "s.prec", "--out", out, "--force", timeout=120).fails_cleanly(
            r"input of this command")
    t.unchanged()


@case("23.3 replay --plot onto the recording it reads refuses and keeps it")
def _(t):
    sim_hand(t)
    t.watch("a.prec")
    r = t.run("replay", "a.prec", "--plot", "a.prec", timeout=60)
    r.expect(err=r"input of this command")
    assert r.rc != 0, "replay --plot over its own input exited 0"
    t.unchanged()


@case("23.3 sim-hand and sim-vist --out onto an existing file need --force, and say so")
def _(t):
    before = sim_hand(t).read_bytes()
    t.run("sim-hand", "--seconds", "1", "--out", "a.prec").fails_cleanly(r"already exists.*--force")
    t.run("sim-vist", "--seconds", "2", "--out", "a.prec", timeout=120).fails_cleanly(r"already exists.*--force")
    assert t.path("a.prec").read_bytes() == before, "a refused command changed the file"
    r = t.run("sim-hand", "--seconds", "1", "--out", "a.prec", "--force")
    assert "RecordingWriterOptions" not in r.err, "an internal option name reached the user"
    r.expect(rc=0)


# --- 23.10: a huge time stamp must not hang replay --summary -------------------------------


@case("23.10 one hand pose with a CLOCK_REALTIME stamp: replay --summary ends and says so")
def _(t):
    p = sim_hand(t)
    data = bytearray(p.read_bytes())
    restamp(data, nth_record_of_kind(data, HAND_POSE, 100), REALTIME_NS)
    p.write_bytes(bytes(data))
    t.watch("a.prec")
    r = t.run("replay", "a.prec", "--summary", timeout=60).expect(rc=0, out=r"1 hand poses left out")
    assert "poses served" in r.out, r.describe()
    t.unchanged()


@case("23.10 the last hand pose far in the future: replay --summary samples coarsely, no hang")
def _(t):
    p = sim_hand(t)
    data = bytearray(p.read_bytes())
    last = [pos for pos, rtype, stream, _, _ in records(bytes(data))
            if rtype == 2 and stream_kinds(bytes(data)).get(stream) == HAND_POSE][-1]
    restamp(data, last, REALTIME_NS)
    p.write_bytes(bytes(data))
    t.run("replay", "a.prec", "--summary", timeout=60).expect(rc=0, out=r"poses served")


# --- 23.11: VIST fusion survives one bad IMU stamp; corruption is reported ---------------------


@case("23.11 one IMU sample with a far-future stamp costs one sample, fusion goes on")
def _(t):
    p = sim_vist(t)
    clean = t.run("track", "vist", "--session", "s.prec", "--json", timeout=120).expect(rc=0)
    data = bytearray(p.read_bytes())
    restamp(data, nth_record_of_kind(data, IMU, 300), REALTIME_NS)
    p.write_bytes(bytes(data))
    r = t.run("track", "vist", "--session", "s.prec", timeout=120).expect(rc=0, out=r"1 isolated time jumps")
    assert "nothing to score" not in r.out, r.describe()
    import json
    before = json.loads(clean.out)
    after = json.loads(t.run("track", "vist", "--session", "s.prec", "--json", timeout=120).expect(rc=0).out)
    assert after["imu_rejected_time_jump"] == 1, after
    # Fusion did not stop: about as many frames fused as without the bad stamp.
    assert after["frames_fused"] >= 0.9 * before["frames_fused"], (before["frames_fused"], after["frames_fused"])


@case("23.11 track vist on a session damaged mid-file reports it (what, byte) and exits 3")
def _(t):
    p = sim_vist(t)
    data = bytearray(p.read_bytes())
    at = len(data) // 3
    data[at:at + 64] = bytes(64)
    p.write_bytes(bytes(data))
    t.watch("s.prec")
    r = t.run("track", "vist", "--session", "s.prec", timeout=120).expect(
        rc=3, err=r"damaged.*at byte \d+", out=r"damaged bytes skipped")
    assert "no ground truth in the session" not in r.out, r.describe()
    t.unchanged()


# --- 23.16: resynchronise after mid-file damage; truncation stays a truncation -----------------


@case("23.16 replay of a recording with a damaged record mid-file reads on and reports the loss")
def _(t):
    p = sim_hand(t)
    data = bytearray(p.read_bytes())
    total = sum(1 for _ in records(bytes(data)))
    pos = nth_record_of_kind(bytes(data), HAND_POSE, 50)
    data[pos + 100] ^= 0xFF
    p.write_bytes(bytes(data))
    r = t.run("replay", "a.prec", timeout=60).expect(rc=3, out=r"Integrity: corrupt: \d+ damaged bytes skipped")
    assert f"at byte {pos}" in r.out and "1 records lost" in r.out, r.describe()
    # Everything else was read: only the damaged record is missing.
    assert f"{total - 2} records" in r.out, (total, r.describe())  # minus End and the damaged one


@case("23.16 a plausible bad length field mid-file is corruption, not 'the writer was cut off'")
def _(t):
    p = sim_hand(t)
    data = bytearray(p.read_bytes())
    pos = nth_record_of_kind(bytes(data), HAND_POSE, 30)
    struct.pack_into("<I", data, pos, len(data) - pos + 5000)  # past the end, under the 16 MiB limit
    p.write_bytes(bytes(data))
    r = t.run("replay", "a.prec", timeout=60).expect(rc=3, out=r"beyond the end of the file")
    assert "cut off" not in r.out, r.describe()


@case("23.16 a truncated tail (writer cut off) still reads up to its last record, exit 0")
def _(t):
    p = sim_hand(t)
    data = p.read_bytes()
    p.write_bytes(data[:len(data) - 777])
    t.run("replay", "a.prec", timeout=60).expect(rc=0, out=r"Integrity: truncated: .*writer was cut off")


@case("23.16 zeroed blocks mid-file (power loss) are skipped and counted")
def _(t):
    p = sim_hand(t)
    data = bytearray(p.read_bytes())
    at = len(data) // 2
    data[at:at + 8192] = bytes(8192)
    p.write_bytes(bytes(data))
    t.run("replay", "a.prec", timeout=60).expect(rc=3, out=r"damaged bytes skipped in 1 region.*records lost")


# --- 23.12: replay streams the file ---------------------------------------------------------


@case("23.12 replay of a long recording runs in bounded memory")
def _(t):
    sim_hand(t, seconds="1800")  # 30 min at 90 Hz: ~500 MiB of records
    size_mb = t.path("a.prec").stat().st_size / 2**20
    t.need(size_mb > 400, f"the recording is only {size_mb:.0f} MiB")
    # The binary maps ~400 MiB of address space before reading a byte; 700 MiB
    # leaves less than the file's size for data. Loading the poses needed more.
    t.run("replay", "a.prec", timeout=240, max_mb=700).expect(rc=0, out=r"poses served")
    t.path("a.prec").unlink()


# --- 23.19 / 23.5: messages and special files -----------------------------------------------


@case("23.19 ANSI escapes in stream names and events do not reach the terminal")
def _(t):
    # A recording by a foreign writer: one event stream named with an escape sequence.
    def rec(rtype, stream, tns, payload):
        head = struct.pack("<IBBHq", len(payload), rtype, 0, stream, tns)
        return head + payload + struct.pack("<I", zlib.crc32(head + payload))
    header = MAGIC + struct.pack("<HHI", 1, 0, 20)
    header += struct.pack("<I", zlib.crc32(header))
    name = b"evil\x1b[2J\x1b]0;pwned\x07"
    meta = b"\x1b[31mred"
    body = rec(1, 0, 0, bytes([7, 0]) + struct.pack("<H", len(name)) + name + struct.pack("<I", len(meta)) + meta)
    body += rec(2, 0, 5, b"text \x1b[2J")
    body += rec(3, 0xFFFF, 0, struct.pack("<Q", 2))
    t.write("e.prec", header + body)
    r = t.run("replay", "e.prec", "--records", "5", timeout=30)
    assert "\x1b" not in r.out and "\x1b" not in r.err, r.describe()
    assert "\x07" not in r.out and "\x07" not in r.err, r.describe()


@case("23.19 a damaged file gives one summary line, not a warning per record")
def _(t):
    p = sim_hand(t)
    data = bytearray(p.read_bytes())
    # Lose the hand stream's definition: every later pose is data of an undefined stream.
    for pos, rtype, stream, _, length in records(bytes(data)):
        if rtype == 1 and data[pos + 16] == HAND_POSE:
            data[pos + 20] ^= 0xFF
            break
    p.write_bytes(bytes(data))
    r = t.run("replay", "a.prec", timeout=60).expect(rc=3, out=r"records were rejected")
    assert r.err.count("\n") < 20, f"{r.err.count(chr(10))} lines of warnings"


@case("23.5 replay of a FIFO or /dev/zero is refused without hanging")
def _(t):
    t.fifo("pipe.prec")
    t.run("replay", "pipe.prec", timeout=20).expect(err=r"FIFO|not a regular file|regular")
    r = t.run("replay", "/dev/zero", timeout=20)
    r.expect(err=r"character device|regular")
    assert r.rc != 0, r.describe()
