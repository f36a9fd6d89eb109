"""Reading the per-case metric files the Makefile writes (dnmetrics --format json)."""

import json
import os

HIGHER_IS_BETTER = {"psnr", "ssim", "fvvdp"}


def case_path(out, kind, method, split, scene, frame, spp, ext):
    return os.path.join(out, kind, method, split, scene, f"{frame}_spp{spp}.{ext}")


def load_case_metrics(out, method, split, cases, spp):
    """[{metric: value}] for every (scene, frame) of `cases`, in order."""
    values = []
    for scene, frame in cases:
        path = case_path(out, "metrics", method, split, scene, frame, spp, "json")
        with open(path) as f:
            result = json.load(f)["results"][0]
        values.append({k: float(v) for k, v in result.items() if k != "file"})
    return values
