#!/usr/bin/env python3
"""The module-graph checker fails where it must: a cycle, a module missing from
the doc, a different link; and passes on a doc it wrote itself."""
import os
import subprocess
import sys
import tempfile

CHECK = sys.argv[1]


def run(graph_text, doc_text, *extra):
    with tempfile.TemporaryDirectory() as d:
        g, doc = os.path.join(d, "graph.txt"), os.path.join(d, "arch.md")
        open(g, "w").write(graph_text)
        open(doc, "w").write(doc_text)
        r = subprocess.run([sys.executable, CHECK, g, doc, *extra], capture_output=True, text=True)
        return r.returncode, r.stderr, open(doc).read()


failures = []
base = "core runtime/core \nsim input/sim core\nvist input/vist core,sim\n"
rc, err, doc = run(base, "# Architecture\n", "--write")
if rc != 0:
    failures.append(f"--write failed: {rc} {err}")
rc, err, _ = run(base, doc)
if rc != 0:
    failures.append(f"a doc written from the same graph does not match: {err}")
rc, err, _ = run(base.replace("core,sim", "core"), doc)
if rc != 1 or "vist" not in err:
    failures.append(f"a changed link was not reported: rc={rc} {err}")
rc, err, _ = run(base + "extra input/extra core\n", doc)
if rc != 1 or "'extra'" not in err:
    failures.append(f"an undocumented module was not reported: rc={rc} {err}")
rc, err, _ = run(base.replace("core runtime/core ", "core runtime/core vist"), doc)
if rc != 1 or "cycle" not in err:
    failures.append(f"a cycle was not reported: rc={rc} {err}")
rc, err, _ = run(base, "# no markers\n")
if rc != 1 or "markers" not in err:
    failures.append(f"a doc without the graph was not reported: rc={rc} {err}")
for f in failures:
    print("FAIL:", f)
print("ok" if not failures else f"{len(failures)} failure(s)")
sys.exit(1 if failures else 0)
