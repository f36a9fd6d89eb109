#!/usr/bin/env python3
"""Where one traced call spent its time: a Chrome trace from
denoise_npy_bench --trace (LibTorch's Kineto profiler) summed up. Prints the
call's wall time, the GPU's busy time (kernels and copies, overlaps merged),
the host time outside any operator, the top-level host operators (dn::
scopes included) by inclusive time, the CUDA runtime calls, and the kernels
by total time. Python's standard library only.

  python3 bench/gpu/trace_summary.py TRACE.json [--top 15]
"""
import argparse
import collections
import json


def merged_length(intervals):
    total, end = 0.0, float("-inf")
    for start, stop in sorted(intervals):
        if stop > end:
            total += stop - max(start, end)
            end = stop
    return total


def top_level(events):
    """Per thread, the operators not inside another one."""
    by_thread = collections.defaultdict(list)
    for e in events:
        by_thread[e["tid"]].append(e)
    out = []
    for ops in by_thread.values():
        end = float("-inf")
        for e in sorted(ops, key=lambda e: (e["ts"], -e["dur"])):
            if e["ts"] >= end:
                out.append(e)
                end = e["ts"] + e["dur"]
    return out


def table(title, totals, counts, top, wall):
    print(f"\n{title}")
    print(f"  {'ms':>9} {'share':>6} {'calls':>6}  name")
    for name, us in sorted(totals.items(), key=lambda kv: -kv[1])[:top]:
        print(f"  {us / 1e3:9.2f} {us / wall:6.1%} {counts[name]:6d}  {name[:90]}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("trace")
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args()
    with open(args.trace) as f:
        events = [e for e in json.load(f)["traceEvents"] if e.get("ph") == "X" and "dur" in e]
    by_cat = collections.defaultdict(list)
    for e in events:
        by_cat[e.get("cat", "")].append(e)
    ops = by_cat["cpu_op"]
    if not ops:
        raise SystemExit(f"{args.trace}: no operators")
    start = min(e["ts"] for e in events)
    wall = max(e["ts"] + e["dur"] for e in events) - start
    gpu = by_cat["kernel"] + by_cat["gpu_memcpy"] + by_cat["gpu_memset"]
    busy = merged_length([(e["ts"], e["ts"] + e["dur"]) for e in gpu])
    print(f"{args.trace}: {wall / 1e3:.1f} ms traced, GPU busy {busy / 1e3:.1f} ms ({busy / wall:.0%}): "
          f"kernels {sum(e['dur'] for e in by_cat['kernel']) / 1e3:.1f} ms, "
          f"copies {sum(e['dur'] for e in by_cat['gpu_memcpy']) / 1e3:.1f} ms")
    outside = wall - merged_length([(e["ts"], e["ts"] + e["dur"]) for e in ops])
    print(f"host time outside any operator (our own loops, waits): {outside / 1e3:.1f} ms")
    for title, group in (("top-level host operators (inclusive)", top_level(ops)),
                         ("CUDA runtime calls", by_cat["cuda_runtime"] + by_cat["cuda_driver"]),
                         ("GPU kernels and copies", gpu)):
        totals, counts = collections.Counter(), collections.Counter()
        for e in group:
            totals[e["name"]] += e["dur"]
            counts[e["name"]] += 1
        if totals:
            table(title, totals, counts, args.top, wall)


if __name__ == "__main__":
    main()
