"""Hostile inputs for the study toolkit: two runs on one study folder, crash and
resume of simulated studies, statistics on ambiguous or degenerate tables,
`study analyze` on damaged session folders, special files as data (issue 23)."""
import csv
import json
import os
import signal
import time

from hostile import case

PT = ["run", "perception-threshold", "--participant", "sim", "--participants", "1", "--seed", "3"]
CSV = "perception-threshold_S01_s1.csv"


def rows(path):
    with open(path, newline="") as f:
        return list(csv.reader(f))


def without_time(table):
    return [r[:-1] for r in table]  # recorded_unix_ns


def wait_for_rows(t, path, n, proc, seconds=30):
    end = time.monotonic() + seconds
    while time.monotonic() < end and proc.poll() is None:
        if path.exists() and len(path.read_bytes().splitlines()) > n:
            return True
        time.sleep(0.005)
    return False


def study_folder(t, out="S"):
    """A finished simulated study (one participant, ~3 s)."""
    t.run(*PT, "--out", out, timeout=120).expect(rc=0)
    return t.path(out)


# --- 23.1: one study folder, one writer ---------------------------------------------------


@case("23.1 a second run on the same --out fails at once and leaves no duplicated trial")
def _(t):
    first = t.start(*PT, "--out", "D")
    try:
        t.need(wait_for_rows(t, t.path("D") / CSV, 2, first), "the first run ended before it wrote trials")
        t.run(*PT, "--out", "D", timeout=30).fails_cleanly(r"in use by another process \(pid \d+\)")
        t.run(*PT, "--out", "D", "--force", timeout=30).fails_cleanly(r"in use by another process")
    finally:
        first.wait(timeout=120)
    assert first.returncode == 0, f"the first run failed: {first.stderr.read().decode()[-500:]}"
    table = rows(t.path("D") / CSV)
    trials = [r[2] for r in table[1:]]
    assert len(trials) == 120 and len(set(trials)) == 120, f"{len(trials)} rows, {len(set(trials))} distinct trials"
    t.run("study", "analyze", "D", "--bootstrap", "0").expect(rc=0)


@case("23.1 study analyze refuses a folder a running study is writing")
def _(t):
    first = t.start("run", "perception-threshold", "--participant", "sim", "--participants", "2", "--seed", "3",
                    "--out", "D")
    try:
        t.need(wait_for_rows(t, t.path("D") / CSV, 2, first), "the study ended before it wrote trials")
        t.run("study", "analyze", "D", "--bootstrap", "0", "--out", "R").fails_cleanly(r"a study is running in")
        assert not t.path("R").exists(), "a report was written from a partial study"
    finally:
        first.wait(timeout=180)


# --- 23.2: crash + resume reproduces the uninterrupted run ------------------------------------


@case("23.2 perception-threshold killed mid-study and resumed equals the uninterrupted run")
def _(t):
    t.run(*PT, "--out", "ref", timeout=120).expect(rc=0)
    run = t.start(*PT, "--out", "D")
    t.need(wait_for_rows(t, t.path("D") / CSV, 30, run), "the run ended before it could be killed")
    os.killpg(run.pid, signal.SIGKILL)
    run.wait()
    killed_at = len(rows(t.path("D") / CSV)) - 1
    t.need(killed_at < 120, "the run finished before the kill landed")
    t.run(*PT, "--out", "D", timeout=120).expect(rc=0, out=r"\b\d+ +\d+ *\|")
    a, b = rows(t.path("ref") / CSV), rows(t.path("D") / CSV)
    assert len(b) == 121, f"{len(b) - 1} trials after the resume"
    assert without_time(a) == without_time(b), "the resumed run answered differently from the uninterrupted one"
    ja = json.loads(t.path("ref/ground_truth.json").read_text())
    jb = json.loads(t.path("D/ground_truth.json").read_text())
    assert ja == jb, "the ground truth differs after a resume"


# --- 23.6: the subject id column ------------------------------------------------------------

WIDE = "1,10,12,15\n2,8,11,11\n3,9,9,14\n4,11,15,16\n5,7,10,12\n"


@case("23.6 stats rm-anova takes Subject / ID / participant_id / a BOM'd header as the id column, and says so")
def _(t):
    t.write("ref.csv", "subject,a,b,c\n" + WIDE)
    ref = t.run("stats", "rm-anova", "--data", "ref.csv", "--json").expect(rc=0, err=r"'subject' holds the subject")
    f_ref = json.loads(ref.out)["f"]
    for name, header in [("cap.csv", "Subject"), ("id.csv", "ID"), ("pid.csv", "participant_id"),
                         ("bom.csv", "\ufeffsubject")]:
        t.write(name, (header + ",a,b,c\n" + WIDE).encode("utf-8"))
        r = t.run("stats", "rm-anova", "--data", name, "--json").expect(rc=0, err=r"holds the subject ids")
        j = json.loads(r.out)
        assert j["f"] == f_ref and j["conditions"] == 3, f"{name}: F {j['f']} vs {f_ref}"


@case("23.6 stats --subject-column names an unusual id column; without it the guess is said on stderr")
def _(t):
    t.write("w.csv", "person,a,b,c\n" + WIDE)
    t.run("stats", "rm-anova", "--data", "w.csv").expect(rc=0, err=r"no subject id column.*--subject-column")
    r = t.run("stats", "rm-anova", "--data", "w.csv", "--subject-column", "person", "--json").expect(rc=0)
    assert json.loads(r.out)["conditions"] == 3
    t.run("stats", "paired-t", "--data", "w.csv", "--subject-column", "nope").fails_cleanly(r"no column 'nope'")
    t.write("two.csv", "subject,ID,a,b\n1,1,2,3\n2,2,4,4\n3,3,1,5\n")
    t.run("stats", "rm-anova", "--data", "two.csv").fails_cleanly(r"both look like subject ids")
    t.write("dup.csv", "subject,a,b\n1,2,3\n1,4,4\n3,1,5\n")
    t.run("stats", "rm-anova", "--data", "dup.csv").fails_cleanly(r"subject '1' appears again")


# --- 23.9: degenerate data are not testable -----------------------------------------------------


@case("23.9 RM-ANOVA / ANOVA / paired t on data without variance say 'not testable', exit 1, print no inf")
def _(t):
    t.write("flat.csv", "A,B,C\n1,1,1\n1,1,1\n1,1,1\n")
    for cmd in ("rm-anova", "anova", "paired-t"):
        r = t.run("stats", cmd, "--data", "flat.csv").expect(rc=1, out=r"not testable")
        assert "inf" not in r.out and "nan" not in r.out.lower(), r.out
    t.write("ceiling.csv", "subject,a,b\n1,1.0,0.5\n2,1.0,0.5\n3,1.0,0.5\n")
    r = t.run("stats", "rm-anova", "--data", "ceiling.csv", "--json").expect(rc=1)
    j = json.loads(r.out)
    assert j["testable"] is False and j["f"] is None and j["p"] is None, j


# --- 23.8: study analyze checks the files -------------------------------------------------------


@case("23.8 study analyze refuses a duplicated trial row, naming file and line")
def _(t):
    s = study_folder(t)
    lines = (s / CSV).read_text().splitlines(keepends=True)
    (s / CSV).write_text("".join(lines + [lines[5]]))
    t.run("study", "analyze", "S", "--bootstrap", "0").fails_cleanly(
        rf"{CSV}:{len(lines) + 1}: trial 4 .* already at .*{CSV}:6")


@case("23.8 study analyze refuses missing trials unless --allow-incomplete, and names them")
def _(t):
    s = study_folder(t)
    lines = (s / CSV).read_text().splitlines(keepends=True)
    (s / CSV).write_text("".join(lines[:11] + lines[14:]))
    t.run("study", "analyze", "S", "--bootstrap", "0").fails_cleanly(r"3 of 120 planned trials are missing \(trial 10-12\)")
    t.run("study", "analyze", "S", "--bootstrap", "0", "--allow-incomplete").expect(rc=0, out=r"trial 10-12")


@case("23.8 study analyze refuses one participant's session split across two files")
def _(t):
    s = study_folder(t)
    lines = (s / CSV).read_text().splitlines(keepends=True)
    (s / CSV).write_text("".join(lines[:60]))
    (s / "perception-threshold_S01_s1_rest.csv").write_text("".join(lines[:1] + lines[60:]))
    (s / "perception-threshold_S01_s1_rest.json").write_text((s / "perception-threshold_S01_s1.json").read_text())
    t.run("study", "analyze", "S", "--bootstrap", "0").fails_cleanly(r"split across two files")


@case("23.8 study analyze refuses out-of-range --guess / --lapse / --threshold with a message")
def _(t):
    study_folder(t)
    for opt, val in [("--guess", "1.5"), ("--guess", "-0.1"), ("--lapse", "1"), ("--lapse-max", "-0.5"),
                     ("--threshold", "2"), ("--threshold", "0"), ("--threshold", "0.3")]:
        t.run("study", "analyze", "S", "--bootstrap", "0", opt, val, "--out", "R").fails_cleanly(
            r"(--guess|--lapse|--lapse-max) .* is outside|--threshold .*never reaches")
        assert not t.path("R").exists(), f"{opt} {val} wrote a report"
    t.run("study", "analyze", "S", "--bootstrap", "0", "--guess", "nan").fails_cleanly(r"not a finite number")


# --- 23.5: special files as study data ----------------------------------------------------------


@case("23.5 psychometric fit / stats / study check refuse /dev/zero and a FIFO without hanging")
def _(t):
    fifo = t.fifo("pipe.csv")
    for args in (["psychometric", "fit", "--data"], ["stats", "rm-anova", "--data"], ["study", "check"]):
        t.run(*args, "/dev/zero", timeout=20, max_mb=1024).fails_cleanly(r"/dev/zero.*(not a regular file|device)")
        t.run(*args, fifo, timeout=20).fails_cleanly(r"pipe\.csv.*(not a regular file|FIFO|pipe)")
    t.run("run", "peg-in-hole", "--participant", "sim", "--design", "/dev/zero", "--out", "P",
          timeout=20).fails_cleanly(r"/dev/zero")
