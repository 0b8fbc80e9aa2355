"""Hostile inputs for `proprio psychometric fit` (issues 23 and 24): counts that
would wrap an int, option values out of range, a threshold the function never
reaches, and data whose likelihood has no unique maximum."""
import os

from hostile import case

GOOD = "level,correct,trials\n1,5,10\n2,6,10\n3,9,10\n4,10,10\n"
SEPARATED = "level,correct,trials\n1,5,10\n2,5,10\n3,10,10\n4,10,10\n"


@case("23.14 counts beyond 2^32 are refused with the file and line, not wrapped")
def _(t):
    t.write("big.csv", "level,correct,trials\n1,5,10\n2,4294967326,4294967336\n")
    r = t.run("psychometric", "fit", "--data", "big.csv").fails_cleanly(r"big\.csv:3: 4294967336 trials .*1000000000")
    assert "30 of 40" not in r.out, "the counts were wrapped"


@case("23.14 counts that sum beyond the limit over rows are refused too")
def _(t):
    rows = "".join(f"2,{600000000},{600000000}\n" for _ in range(2))
    t.write("sum.csv", "level,correct,trials\n1,5,10\n" + rows)
    t.run("psychometric", "fit", "--data", "sum.csv").fails_cleanly(r"sum\.csv:4: .*in all up to this row")


@case("24 --bootstrap -3 is refused with a range")
def _(t):
    t.write("d.csv", GOOD)
    for v in ("-3", "5", "1000001"):
        t.run("psychometric", "fit", "--data", "d.csv", "--bootstrap", v).fails_cleanly(
            rf"--bootstrap {v}: give 0 \(no bootstrap\) or from 10 to 1000000")


@case("24 --gof -1 is refused with a range")
def _(t):
    t.write("d.csv", GOOD)
    t.run("psychometric", "fit", "--data", "d.csv", "--gof", "-1").fails_cleanly(r"--gof -1: give 0 .* from 1 to")


@case("24 --threshold below the guess rate names the file")
def _(t):
    t.write("d.csv", GOOD)
    t.run("psychometric", "fit", "--data", "d.csv", "--threshold", "0.4").fails_cleanly(
        r"d\.csv \(--threshold 0\.4\): the function never reaches proportion 0\.4")


@case("24 perfectly separated data warn that the maximum is not unique, and the CI has width")
def _(t):
    t.write("sep.csv", SEPARATED)
    r = t.run("psychometric", "fit", "--data", "sep.csv", "--bootstrap", "200", "--json").expect(
        rc=0, err=r"sep\.csv: the maximum likelihood is not unique: .*between levels 2 and 3")
    import json
    j = json.loads(r.out)
    assert j["unique_maximum"] is False, j
    lo, hi = j["bootstrap"]["threshold"]["percentile"]
    assert hi - lo > 0.3, f"bootstrap interval [{lo}, {hi}] has collapsed"


@case("24 well-behaved data give no warning")
def _(t):
    t.write("pal.csv", "level,correct,trials\n0.01,59,100\n0.03,53,100\n0.05,68,100\n0.07,83,100\n"
            "0.09,92,100\n0.11,99,100\n")
    t.run("psychometric", "fit", "--data", "pal.csv", "--bootstrap", "100", "--gof", "100").expect(
        rc=0, out=r"goodness of fit p = ", no_err=r"warning")


@case("23 --plot naming the --data file is refused and the CSV is left as it was")
def _(t):
    t.write("d.csv", GOOD)
    t.watch("d.csv")
    t.run("psychometric", "fit", "--data", "d.csv", "--plot", "d.csv").fails_cleanly(
        r"refusing to write the plot to .*d\.csv.*input of this command")
    t.write("link.csv", GOOD)
    os.symlink("link.csv", t.path("alias.svg"))
    t.watch("link.csv")
    t.run("psychometric", "fit", "--data", "link.csv", "--plot", "alias.svg").fails_cleanly(
        r"refusing to write the plot to .*alias\.svg.*input of this command")


@case("24 a bootstrap or test that would simulate more than 2e9 trials is refused at once, not a hang")
def _(t):
    t.write("huge.csv", "level,correct,trials\n1,300000000,500000000\n2,450000000,500000000\n")
    t.run("psychometric", "fit", "--data", "huge.csv", "--bootstrap", "1999", timeout=20).fails_cleanly(
        r"huge\.csv: a bootstrap of 1999 data sets x 1000000000 trials would simulate 1999000000000 trials, more "
        r"than the limit of 2000000000; use at most 2 data sets")
    t.run("psychometric", "fit", "--data", "huge.csv", "--gof", "3", timeout=20).fails_cleanly(
        r"goodness-of-fit test of 3 data sets .* more than the limit of 2000000000")
