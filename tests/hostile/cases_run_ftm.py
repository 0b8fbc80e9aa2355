"""The FTM glove in `proprio run` (issue 27 §4): `--hands ftm [sim|device]`,
`--ftm-calibration` and the simulated peg-in-hole study's `--tracker ftm`.
A hostile calibration file (missing, a folder, a FIFO, /dev/zero, broken TOML,
NaN or inf, the other hand's) stops the run with the file, and where it can
the line and key; a value the command would silently ignore is refused; no
bad value touches a study folder (docs/ftm.md)."""
from hostile import case

RUN = ["run", "half-cylinder", "--headless", "--frames", "2", "--out", "f"]
PEG = ["run", "peg-in-hole", "--participant", "sim", "--participants", "1"]
IMUS = ["dorsum", "thumb_metacarpal", "index_proximal", "middle_proximal"]
BENDS = ["thumb_mcp", "index_pip", "middle_pip"]


def calibration(hand="right", length="0.19", field="20.0, 0.0, -45.0", q="1.0, 0.0, 0.0, 0.0", beta1="0.05"):
    """An FTM calibration file as `proprio calibrate ftm` writes one (input/ftm/src/ftm_calibration.cpp),
    nominal values, with any one value replaced."""
    s = (f'[ftm]\nhand = "{hand}"\nhand_length_m = {length}\nhand_width_m = 0.09\nsubject = "hostile"\n'
         f"earth_field_world_uT = [{field}]\n")
    for i in IMUS:
        s += (f"\n[imu.{i}]\nq_imu_segment_wxyz = [{q}]\nhard_iron_uT = [0.0, 0.0, 0.0]\n"
              "soft_iron_inv = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n")
    for b in BENDS:
        s += f"\n[bend.{b}]\nbeta0_rad = 0.0\nbeta1_rad_per_pF = {beta1}\n"
    return s


def ftm_run(t, *extra, timeout=90):
    return t.run(*RUN, *extra, timeout=timeout)


@case("27 run --hands ftm usb: refused with the choices (sim, device)")
def _(t):
    ftm_run(t, "--hands", "ftm", "usb").fails_cleanly(r"--hands ftm 'usb'.*sim.*device")


@case("27 run --hands ftm device without --ftm-calibration: refused, naming 'proprio calibrate ftm'")
def _(t):
    ftm_run(t, "--hands", "ftm", "device").fails_cleanly(r"--ftm-calibration FILE.*proprio calibrate ftm")


@case("27 --ftm-calibration that does not exist / is a folder: refused, the path named")
def _(t):
    for inp in ("device", "sim"):
        ftm_run(t, "--hands", "ftm", inp, "--ftm-calibration", "nope.toml").fails_cleanly(
            r"'nope.toml' does not exist")
    t.path("cal_dir").mkdir()
    ftm_run(t, "--hands", "ftm", "device", "--ftm-calibration", "cal_dir").fails_cleanly(r"'cal_dir' is a directory")


@case("27 --ftm-calibration a FIFO: refused at once, no hang")
def _(t):
    fifo = t.fifo("ftm.toml")
    r = ftm_run(t, "--hands", "ftm", "device", "--ftm-calibration", fifo, timeout=30).fails_cleanly(r"ftm.toml.*FIFO")
    if r.seconds > 20:
        raise AssertionError(f"took {r.seconds:.1f} s to refuse a FIFO")


@case("27 --ftm-calibration /dev/zero: refused as a character device")
def _(t):
    ftm_run(t, "--hands", "ftm", "device", "--ftm-calibration", "/dev/zero", timeout=30).fails_cleanly(
        r"/dev/zero.*character device")


@case("27 --ftm-calibration of malformed TOML or binary bytes: refused with the file and line")
def _(t):
    t.write("broken.toml", "[ftm\nbeta1 = \n")
    ftm_run(t, "--hands", "ftm", "sim", "--ftm-calibration", "broken.toml").fails_cleanly(r"broken.toml:\d+")
    t.write("binary.toml", bytes(range(256)) * 8)
    ftm_run(t, "--hands", "ftm", "device", "--ftm-calibration", "binary.toml").fails_cleanly(r"binary.toml")
    t.write("empty.toml", "")
    ftm_run(t, "--hands", "ftm", "device", "--ftm-calibration", "empty.toml").fails_cleanly(r"empty.toml.*'ftm' is missing")


@case("27 --ftm-calibration with NaN / inf values: refused with the file, line and key")
def _(t):
    bad = {
        "beta1_nan.toml": (calibration(beta1="nan"), r"beta1_nan.toml:\d+.*bend\.thumb_mcp\.beta1_rad_per_pF"),
        "beta1_zero.toml": (calibration(beta1="0.0"), r"beta1_zero.toml:\d+.*beta1_rad_per_pF.*must not be 0"),
        "q_inf.toml": (calibration(q="inf, 0.0, 0.0, 0.0"), r"q_inf.toml:\d+.*imu\.dorsum\.q_imu_segment_wxyz"),
        "field_nan.toml": (calibration(field="nan, 0.0, -45.0"), r"field_nan.toml:\d+.*ftm\.earth_field_world_uT"),
        "length_nan.toml": (calibration(length="nan"), r"length_nan.toml:\d+.*ftm\.hand_length_m"),
        "length_neg_inf.toml": (calibration(length="-inf"), r"length_neg_inf.toml:\d+.*ftm\.hand_length_m"),
    }
    for name, (text, err) in bad.items():
        t.write(name, text)
        for inp in ("sim", "device"):
            ftm_run(t, "--hands", "ftm", inp, "--ftm-calibration", name).fails_cleanly(err)


@case("27 --ftm-calibration for the other hand: refused, the file and both hands named")
def _(t):
    t.write("left.toml", calibration(hand="left"))
    ftm_run(t, "--hands", "ftm", "sim", "--ftm-calibration", "left.toml").fails_cleanly(
        r"--hand right --ftm-calibration left.toml.*right hand.*left-hand calibration")


@case("27 a good --ftm-calibration runs a simulated wearer (the control for the cases above)")
def _(t):
    t.write("good.toml", calibration())
    ftm_run(t, "--hands", "ftm", "sim", "--ftm-calibration", "good.toml").expect(
        rc=0, out=r"hands: ftm.*tracked hand in \d+ of them")


@case("27 --hands ftm device with no board on USB: runs untracked, no crash, no hang")
def _(t):
    t.write("good.toml", calibration())
    ftm_run(t, "--hands", "ftm", "device", "--ftm-calibration", "good.toml").expect(
        rc=0, out=r"hands: ftm.*tracked hand in \d+ of them")


@case("27 --ftm-calibration without --hands ftm, or empty: refused, not silently ignored")
def _(t):
    t.write("good.toml", calibration())
    ftm_run(t, "--ftm-calibration", "good.toml").fails_cleanly(r"--ftm-calibration applies only to --hands ftm")
    ftm_run(t, "--hands", "glove", "sim", "--ftm-calibration", "good.toml").fails_cleanly(
        r"--ftm-calibration applies only to --hands ftm.*glove")
    ftm_run(t, "--hands", "ftm", "sim", "--ftm-calibration", "").fails_cleanly(r"--ftm-calibration ''")


@case("27 peg-in-hole --tracker FTM / 'ftm ' / '': refused with the choices, the study folder untouched")
def _(t):
    t.write("P/keep.csv", "participant,trial\nsim01,1\n")
    t.watch("P")
    for value, err in (("FTM", r"tracker 'FTM'.*ideal.*ftm"), ("ftm ", r"tracker 'ftm '"), ("", r"--tracker ''"),
                       ("nan", r"tracker 'nan'")):
        t.run(*PEG, "--tracker", value, "--out", "P", "--force", timeout=60).fails_cleanly(err)


@case("27 --tracker ftm outside the simulated peg-in-hole study: refused, --hands ftm named")
def _(t):
    ftm_run(t, "--tracker", "ftm").fails_cleanly(r"--tracker applies only to .*peg-in-hole --participant sim")
    t.run("run", "peg-in-hole", "--headless", "--frames", "1", "--out", "f", "--tracker", "ftm",
          timeout=60).fails_cleanly(r"--tracker applies only to")
    t.run("run", "peg-in-hole", "--participant", "P01", "--headless", "--tracker", "ftm", "--out", "P",
          timeout=60).fails_cleanly(r"simulated participants.*--hands ftm")
    assert not t.path("P").exists(), "a refused real-participant run created its session folder"


@case("27 peg-in-hole design [study] tracker = nan / \"\" / \"FTM\": refused with the file and key")
def _(t):
    for name, value, err in (("nan.toml", "nan", r"nan.toml:\d+.*study\.tracker.*string"),
                             ("empty.toml", '""', r"empty.toml.*\[study\] tracker.*tracker ''"),
                             ("upper.toml", '"FTM"', r"upper.toml.*\[study\] tracker.*'FTM'")):
        t.write(name, f"[study]\ntracker = {value}\n")
        t.run(*PEG, "--design", name, "--out", "P", timeout=60).fails_cleanly(err)
    assert not t.path("P").exists(), "a refused design created the study folder"
    t.write("real.toml", '[study]\ntracker = "ftm"\n')
    t.run("run", "peg-in-hole", "--participant", "P01", "--headless", "--design", "real.toml", "--out", "P",
          timeout=60).fails_cleanly(r"\[study\] tracker.*simulated participants")
