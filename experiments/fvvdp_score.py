#!/usr/bin/env python3
"""FovVideoVDP (pyfvvdp) of results against references, as still images, for
the Makefile's pairs with a reference each (sequences: dnmetrics --fvvdp).

  fvvdp_score.py --display NAME --out OUT.json REF1 RES1 [REF2 RES2 ...]
      Both images go through the same display encoding dnmetrics uses for FLIP:
      Reinhard v / (1 + v) on linear radiance, then the sRGB curve; pyfvvdp then
      models an SDR display NAME (default standard_4k). Writes
      {"display", "results": [{"reference", "file", "fvvdp"}]} (JOD, higher is better).
Runs with the interpreter that has pyfvvdp (FVVDP_PYTHON in the Makefile).
"""

import argparse
import json
import os
import sys

import numpy as np

from exrutil import ExrError, fail, read_color


def display_encode(rgb):
    v = np.clip(np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0), 0.0, None)
    v = v / (1 + v)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055).astype(np.float32)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--display", default="standard_4k")
    parser.add_argument("--out", required=True)
    parser.add_argument("pairs", nargs="+")
    args = parser.parse_args()
    if len(args.pairs) % 2:
        fail("fvvdp_score: give REF RESULT pairs")
    import torch
    import pyfvvdp
    metric = pyfvvdp.fvvdp(display_name=args.display, heatmap=None, device=torch.device("cpu"))
    results = []
    for ref_path, test_path in zip(args.pairs[::2], args.pairs[1::2]):
        try:
            ref, test = display_encode(read_color(ref_path)), display_encode(read_color(test_path))
        except ExrError as error:
            fail(f"fvvdp_score: {error}")
        if ref.shape != test.shape:
            fail(f"fvvdp_score: {test_path}: size {test.shape[:2]} differs from {ref_path} {ref.shape[:2]}")
        jod, _ = metric.predict(torch.from_numpy(test), torch.from_numpy(ref), dim_order="HWC")
        results.append({"reference": ref_path, "file": test_path, "fvvdp": float(jod)})
    tmp = f"{args.out}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        json.dump({"display": args.display, "results": results}, f, indent=1)
    os.replace(tmp, args.out)


if __name__ == "__main__":
    sys.exit(main())
