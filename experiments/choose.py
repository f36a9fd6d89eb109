#!/usr/bin/env python3
"""Picks a tuned method's best setting on the tuning split.

  choose.py PLAN.json METHOD SPP METRIC
      Reads the metrics of every candidate setting of METHOD (plan.json "sweeps") on
      the tuning split at SPP, picks the best mean METRIC (ties: fewer network
      evaluations), and writes OUT/args/METHOD_sppSPP.args (the winner's arguments,
      rewritten only when they change) and OUT/choice/METHOD_sppSPP.json (every
      candidate's mean metrics, for the report).
"""

import json
import os
import sys

from configure import write_if_changed
from metrics_io import HIGHER_IS_BETTER, load_case_metrics


def main():
    plan_path, method, spp, metric = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
    with open(plan_path) as f:
        plan = json.load(f)
    out = plan["out"]
    cases = [(scene, frame) for scene, info in plan["scenes"]["tune"].items()
             if spp in info["spps"] for frame in info["frames"]]
    rows = []
    for sweep in plan["sweeps"]:
        if sweep["parent"] != method:
            continue
        values = load_case_metrics(out, sweep["name"], "tune", cases, spp)
        means = {k: sum(v[k] for v in values) / len(values) for k in values[0]}
        rows.append({"name": sweep["name"], "steps": sweep["steps"], "skip": sweep["skip"],
                     "args": sweep["spp_args"][str(spp)], "frames": len(values), "mean": means})
    if not rows:
        print(f"choose: {plan_path}: no candidates for {method}", file=sys.stderr)
        sys.exit(1)
    if metric not in rows[0]["mean"]:
        print(f"choose: TUNE_METRIC={metric} is not one of {sorted(rows[0]['mean'])}", file=sys.stderr)
        sys.exit(1)
    sign = -1 if metric in HIGHER_IS_BETTER else 1
    best = min(rows, key=lambda r: (sign * r["mean"][metric], r["steps"] - r["skip"]))
    write_if_changed(os.path.join(out, "args", f"{method}_spp{spp}.args"), " ".join(best["args"]) + "\n")
    choice = {"method": method, "spp": spp, "metric": metric, "best": best["name"], "candidates": rows}
    write_if_changed(os.path.join(out, "choice", f"{method}_spp{spp}.json"), json.dumps(choice, indent=1) + "\n")


if __name__ == "__main__":
    main()
