"""`proprio bench ftm` and `proprio sim-ftm` against bad numbers, NaN and inf,
unknown names, and output paths that must not be written (a folder, a FIFO,
/dev/zero, a missing folder, a full device)."""
from hostile import case

SIM = ["sim-ftm", "--seconds", "2"]


@case("bench ftm: bad numbers, NaN, inf and unknown cases are refused with the option named")
def _(t):
    for option, values in [("--subjects", ["0", "6", "-1", "nan", "2.5"]),
                           ("--minutes", ["nan", "inf", "-1", "0", "61", "1min"]),
                           ("--seed", ["-1", "nan", "1e3"])]:
        for v in values:
            t.run("bench", "ftm", option, v, timeout=20).fails_cleanly(option)
    t.run("bench", "ftm", "--cases", "bogus", timeout=20).fails_cleanly(r"unknown FTM bench case 'bogus'")
    t.run("bench", "ftm", "--cases", ",", timeout=20).fails_cleanly(r"--cases")


@case("sim-ftm: bad numbers, NaN, inf, an unknown protocol or magnet are refused, nothing written")
def _(t):
    for option, values in [("--seconds", ["nan", "inf", "0", "-3", "1e9"]),
                           ("--subject", ["-1", "15", "nan"]),
                           ("--protocol", ["walking", ""]),
                           ("--seed", ["-2", "inf"])]:
        for v in values:
            t.run(*SIM, option, v, "--out", "s.prec", timeout=20).fails_cleanly(option)
            assert not t.path("s.prec").exists(), f"{option} {v!r} wrote a file"
    t.run(*SIM, "--magnets", "drill,magnet", "--out", "s.prec", timeout=20).fails_cleanly(r"unknown object 'magnet'")
    assert not t.path("s.prec").exists()


@case("sim-ftm: --out a folder, a FIFO, /dev/zero or in a missing folder is refused without a hang")
def _(t):
    t.path("adir").mkdir()
    t.run(*SIM, "--out", "adir", timeout=30).fails_cleanly(r"adir.*director")
    fifo = t.fifo("pipe.prec")
    t.run(*SIM, "--out", str(fifo), timeout=30).fails_cleanly(r"pipe\.prec")
    t.run(*SIM, "--out", "/dev/zero", timeout=30).fails_cleanly(r"/dev/zero")
    t.run(*SIM, "--out", "/dev/zero", "--force", timeout=30).fails_cleanly(r"/dev/zero")
    t.run(*SIM, "--out", "missing/s.prec", timeout=30).fails_cleanly(r"missing/s\.prec")


@case("sim-ftm: an unwritable --truth or --plot is an error, not a silent success")
def _(t):
    t.path("adir").mkdir()
    t.run(*SIM, "--out", "a.prec", "--truth", "/dev/full", timeout=60).fails_cleanly(r"--truth")
    t.run(*SIM, "--out", "b.prec", "--plot", "adir", timeout=60).fails_cleanly(r"plot.*adir")


@case("sim-ftm: a short session is written and readable by replay")
def _(t):
    t.run(*SIM, "--out", "s.prec", "--truth", "t.csv", timeout=120).expect(rc=0, out=r"sim-ftm: \d+ samples")
    t.run("replay", "s.prec", timeout=60).expect(rc=0, out=r"ftm/imu/dorsum")
    t.watch("s.prec")
    t.run(*SIM, "--out", "s.prec", timeout=60).fails_cleanly(r"s\.prec.*exists")
    head = t.path("t.csv").read_text().splitlines()[0]
    assert head.startswith("time_s,phase,thumb_cmc_flexion_rad"), head
