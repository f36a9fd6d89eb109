#!/usr/bin/env python3
"""libdenoise's folders include each other in one direction only: reads every
`#include "dn/<part>/..."` in libdenoise/src/<part> and
libdenoise/include/dn/<part>, and fails naming the cycle (with the files that
make each arrow) where two folders include each other, directly or through a
longer cycle. Prints the folder graph.

  include_layers_check.py --source DIR
"""
import argparse
import os
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s*"dn/([A-Za-z0-9_]+)/[^"]+"', re.M)


def folder_graph(root):
    """{folder: {folder it includes: [files that include it]}}."""
    graph = {}
    for base in (os.path.join(root, "src"), os.path.join(root, "include", "dn")):
        if not os.path.isdir(base):
            continue
        for part in sorted(os.listdir(base)):
            top = os.path.join(base, part)
            if not os.path.isdir(top):
                continue
            edges = graph.setdefault(part, {})
            for folder, _, files in os.walk(top):
                for name in sorted(files):
                    path = os.path.join(folder, name)
                    with open(path, encoding="utf-8", errors="replace") as f:
                        for target in INCLUDE.findall(f.read()):
                            if target != part:
                                edges.setdefault(target, []).append(os.path.relpath(path, root))
    return graph


def cycles(graph):
    """The strongly connected components of more than one folder (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, {})):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def shortest_path(graph, start, goal, members):
    """The shortest path of folders from start to goal within members."""
    paths, seen = [[start]], {start}
    while paths:
        path = paths.pop(0)
        if path[-1] == goal:
            return path
        for nxt in sorted(graph.get(path[-1], {})):
            if nxt in members and nxt not in seen:
                seen.add(nxt)
                paths.append(path + [nxt])
    return None


def cycle_paths(graph, component):
    """The shortest cycle through each arrow of the component, each once."""
    members, found = set(component), []
    for a in component:
        for b in sorted(graph.get(a, {})):
            back = shortest_path(graph, b, a, members) if b in members else None
            if back:
                cycle = [a] + back[:-1]
                first = cycle.index(min(cycle))
                cycle = cycle[first:] + cycle[:first]
                if cycle not in found:
                    found.append(cycle)
    return [cycle + [cycle[0]] for cycle in sorted(found, key=lambda c: (len(c), c))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--source", required=True, help="the project's source folder")
    args = ap.parse_args()
    graph = folder_graph(os.path.join(args.source, "libdenoise"))
    for part in sorted(graph):
        print(f"{part} -> {', '.join(sorted(graph[part])) or '(none)'}")
    found = cycles(graph)
    for component in found:
        for path in cycle_paths(graph, component):
            print(f"FAIL: libdenoise folders include each other: {' -> '.join(path)}")
            for a, b in zip(path, path[1:]):
                print(f"  {a} -> {b}: {', '.join(sorted(set(graph[a][b])))}")
    if not found:
        print("ok: the folders' includes point one way (no cycle)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
