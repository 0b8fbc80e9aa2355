#!/usr/bin/env python3
"""Side-by-side timing of a 1999-sample parametric bootstrap with BCa intervals
plus the Monte Carlo goodness-of-fit test: `proprio psychometric fit` against
Debian's psignifit 2.5.6 (`apt-get install psignifit`; not a build dependency).

Both fit a 2AFC Weibull with the lapse rate fixed at 0 and read the threshold
at 75 % correct (psignifit's cut 0.5) from the same data sets: the Palamedes
and psignifit demo sets and seeded simulated observers (6 levels x 40 trials,
8 x 20, 5 x 100). Each command runs REPEATS times, the two tools in turn, and
the report gives, per data set and tool, the medians of wall and CPU time
(user + system of the finished child) of the whole command and of the same
command with the bootstrap turned off ("start"), and "work" = whole - start,
a difference of the two printed medians so that the table adds up; the ratios
proprio / psignifit are taken from those same figures.

    python3 tests/bench/psignifit_vs_proprio.py build/dev/tools/proprio/proprio [REPEATS]
"""
import os
import random
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

SAMPLES = 1999


def weibull_psi(x, alpha, beta):
    import math
    return 0.5 + 0.5 * (1.0 - math.exp(-((x / alpha) ** beta)))


def data_sets():
    sets = {
        "palamedes-demo": [(0.01, 59, 100), (0.03, 53, 100), (0.05, 68, 100), (0.07, 83, 100), (0.09, 92, 100),
                           (0.11, 99, 100)],
        "psignifit-demo": [(1.0, 20, 40), (1.6, 23, 40), (1.8, 35, 60), (2.5, 40, 60), (3.0, 49, 60),
                           (3.5, 52, 60), (4.0, 40, 40), (6.0, 40, 40)],
    }
    rng = random.Random(24)
    for name, levels, trials in [("sim-6x40", [1.5, 3, 4.5, 6, 7.5, 9], 40),
                                 ("sim-8x20", [1, 2, 3, 4, 5, 6, 7, 8], 20),
                                 ("sim-5x100", [2, 3.5, 5, 6.5, 8], 100)]:
        rows = []
        for x in levels:
            p = weibull_psi(x, 5.0, 3.0)
            rows.append((x, sum(rng.random() < p for _ in range(trials)), trials))
        sets[name] = rows
    return sets


def timed(argv):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit(f"{' '.join(argv)} failed ({done.returncode}): {done.stderr.decode(errors='replace')[-500:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    proprio = sys.argv[1]
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 7
    psignifit = shutil.which("psignifit")
    if not psignifit:
        sys.exit("psignifit is not installed (apt-get install psignifit); nothing was timed")
    work = tempfile.mkdtemp(prefix="psignifit_vs_proprio_")
    load_before = open("/proc/loadavg").read().split()[:3]
    print(f"{time.strftime('%Y-%m-%d %H:%M')}, {SAMPLES} bootstrap samples + goodness of fit, {repeats} runs each, "
          f"{os.cpu_count()} CPUs, load average before {' '.join(load_before)}; medians in ms")
    print("whole = the command with the bootstrap and test; start = the same fit with them off; work = whole - start "
          "(a difference of the two medians printed, so the columns add up); ratio = proprio / psignifit")
    header = f"{'data set':16} {'tool':9} {'whole wall':>10} {'whole cpu':>9} {'start wall':>10} {'start cpu':>9} " \
             f"{'work wall':>9} {'work cpu':>8}"
    print(header)
    ratios = {"wall": [], "cpu": [], "work_wall": [], "work_cpu": []}
    summary = []
    for name, rows in data_sets().items():
        csv = os.path.join(work, name + ".csv")
        dat = os.path.join(work, name + ".dat")
        with open(csv, "w") as f:
            f.write("level,correct,trials\n" + "".join(f"{x},{k},{n}\n" for x, k, n in rows))
        with open(dat, "w") as f:
            f.write("".join(f"{x} {k / n:.10f} {n}\n" for x, k, n in rows))
        prefs = {}
        for runs in (SAMPLES, 0):
            prefs[runs] = os.path.join(work, f"{name}.{runs}.prefs")
            with open(prefs[runs], "w") as f:
                f.write(f"#shape Weibull\n#n_intervals 2\n#fix_lambda 0\n#cuts 0.5\n#runs {runs}\n"
                        "#random_seed 1\n")
        commands = {
            ("proprio", SAMPLES): [proprio, "psychometric", "fit", "--data", csv, "--model", "weibull", "--guess",
                                   "0.5", "--lapse", "0", "--threshold", "0.75", "--bootstrap", str(SAMPLES),
                                   "--gof", str(SAMPLES), "--seed", "1"],
            ("proprio", 0): [proprio, "psychometric", "fit", "--data", csv, "--model", "weibull", "--guess", "0.5",
                             "--lapse", "0", "--threshold", "0.75"],
            ("psignifit", SAMPLES): [psignifit, dat, prefs[SAMPLES]],
            ("psignifit", 0): [psignifit, dat, prefs[0]],
        }
        times = {key: [] for key in commands}
        for key in commands:  # warm-up
            timed(commands[key])
        for _ in range(repeats):
            for key in commands:  # in turn, so drift hits all four alike
                times[key].append(timed(commands[key]))
        med = {key: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
               for key, v in times.items()}
        row = {}
        for tool in ("proprio", "psignifit"):
            whole_w, whole_c = med[(tool, SAMPLES)]
            start_w, start_c = med[(tool, 0)]
            row[tool] = (whole_w, whole_c, start_w, start_c, whole_w - start_w, whole_c - start_c)
            print(f"{name:16} {tool:9} " + " ".join(f"{1e3 * v:{w}.1f}" for v, w in
                                                      zip(row[tool], (10, 9, 10, 9, 9, 8))))
        p, s = row["proprio"], row["psignifit"]
        r = {"wall": p[0] / s[0], "cpu": p[1] / s[1],
             "work_wall": p[4] / s[4] if s[4] > 0 else float("nan"),
             "work_cpu": p[5] / s[5] if s[5] > 0 else float("nan")}
        for k in ratios:
            ratios[k].append(r[k])
        summary.append(f"{name:16} ratio whole wall {r['wall']:.2f}, whole cpu {r['cpu']:.2f}, "
                       f"work wall {r['work_wall']:.2f}, work cpu {r['work_cpu']:.2f}")
    print("\n".join(summary))
    print("median ratio proprio / psignifit: whole command wall {:.2f}, cpu {:.2f}; bootstrap + gof work "
          "wall {:.2f}, cpu {:.2f}".format(*(statistics.median(ratios[k]) for k in
                                              ("wall", "cpu", "work_wall", "work_cpu"))))
    print(f"load average after {' '.join(open('/proc/loadavg').read().split()[:3])}")
    shutil.rmtree(work)


if __name__ == "__main__":
    main()
