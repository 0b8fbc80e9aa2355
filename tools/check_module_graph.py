#!/usr/bin/env python3
"""Checks that docs/architecture.md draws the module graph the build has.

The build writes <build>/module_graph.txt (cmake/ProprioOptions.cmake,
proprio_write_module_graph): one line per library, "<name> <folder> <deps>",
with the proprio modules each one links. This script

  * fails on a dependency cycle (every module must depend only on modules below it);
  * fails when the graph between the markers in docs/architecture.md differs
    from the build's (a module missing, a different folder or different links);
  * with --write, rewrites that part of the doc from the build's graph.

Usage: check_module_graph.py <build>/module_graph.txt docs/architecture.md [--write]
Exit status: 0 the doc matches, 1 a mismatch or a cycle, 2 a usage or file error.
"""
import argparse
import sys

BEGIN = "<!-- module-graph:begin (tools/check_module_graph.py --write regenerates this part) -->"
END = "<!-- module-graph:end -->"


def read_build_graph(path):
    graph = {}
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            parts = line.split()
            if not parts:
                continue
            if len(parts) not in (2, 3):
                raise ValueError(f"{path}:{n}: expected '<name> <folder> [deps]', got {line.strip()!r}")
            name, folder = parts[0], parts[1]
            deps = sorted(d for d in (parts[2].split(",") if len(parts) == 3 else []) if d)
            graph[name] = (folder, deps)
    # Links to helper targets that are not modules (an INTERFACE target inside a
    # module, say) are not edges of the module graph.
    return {n: (f, [d for d in deps if d in graph]) for n, (f, deps) in graph.items()}


def find_cycle(graph):
    state = {}  # 1 visiting, 2 done

    def visit(node, path):
        state[node] = 1
        for dep in graph.get(node, ("", []))[1]:
            if state.get(dep) == 1:
                return path + [node, dep]
            if state.get(dep) is None and dep in graph:
                cycle = visit(dep, path + [node])
                if cycle:
                    return cycle
        state[node] = 2
        return None

    for node in sorted(graph):
        if state.get(node) is None:
            cycle = visit(node, [])
            if cycle:
                return cycle[cycle.index(cycle[-1]):]
    return None


def levels(graph):
    """Level 0 depends on no proprio module; level k on modules below k."""
    level = {}

    def of(node):
        if node not in level:
            deps = [d for d in graph[node][1] if d in graph]
            level[node] = 1 + max((of(d) for d in deps), default=-1)
        return level[node]

    for node in graph:
        of(node)
    return level


def render(graph):
    level = levels(graph)
    order = sorted(graph, key=lambda n: (level[n], graph[n][0], n))
    lines = [BEGIN, "", "```mermaid", "graph BT"]
    for name in order:
        for dep in graph[name][1]:
            lines.append(f"  {name} --> {dep}")
    lines += ["```", "", "| level | module (`proprio::…`) | folder | links these modules |", "|---|---|---|---|"]
    for name in order:
        folder, deps = graph[name]
        lines.append(f"| {level[name]} | `{name}` | `{folder}` | {', '.join(deps) if deps else '—'} |")
    lines += ["", END]
    return "\n".join(lines)


def doc_graph(text, doc_path):
    if BEGIN not in text or END not in text:
        raise ValueError(f"{doc_path}: the markers {BEGIN!r} and {END!r} are missing")
    body = text[text.index(BEGIN) : text.index(END)]
    graph = {}
    for line in body.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 4 or not cells[1].startswith("`"):
            continue
        name, folder = cells[1].strip("`"), cells[2].strip("`")
        deps = sorted(d.strip() for d in cells[3].split(",") if d.strip() not in ("", "—"))
        graph[name] = (folder, deps)
    return graph


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("graph")
    ap.add_argument("doc")
    ap.add_argument("--write", action="store_true", help="rewrite the doc's graph from the build's")
    args = ap.parse_args()
    try:
        graph = read_build_graph(args.graph)
        with open(args.doc, encoding="utf-8") as f:
            text = f.read()
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if not graph:
        print(f"error: {args.graph} lists no modules", file=sys.stderr)
        return 2
    cycle = find_cycle(graph)
    if cycle:
        print("error: dependency cycle: " + " -> ".join(cycle), file=sys.stderr)
        return 1
    if args.write:
        if BEGIN in text and END in text:
            text = text[: text.index(BEGIN)] + render(graph) + text[text.index(END) + len(END) :]
        else:
            text = text.rstrip("\n") + "\n\n" + render(graph) + "\n"
        with open(args.doc, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"{args.doc}: module graph written ({len(graph)} modules)")
        return 0
    try:
        documented = doc_graph(text, args.doc)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    problems = []
    for name in sorted(set(graph) | set(documented)):
        if name not in documented:
            problems.append(f"module '{name}' ({graph[name][0]}) is built but not in the doc")
        elif name not in graph:
            problems.append(f"module '{name}' is in the doc but not built")
        elif graph[name] != documented[name]:
            problems.append(f"module '{name}': built as {graph[name]}, the doc says {documented[name]}")
    if problems:
        for p in problems:
            print(f"error: {p}", file=sys.stderr)
        print(f"run: {sys.argv[0]} {args.graph} {args.doc} --write", file=sys.stderr)
        return 1
    print(f"{args.doc}: the module graph matches the build ({len(graph)} modules, no cycle)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
