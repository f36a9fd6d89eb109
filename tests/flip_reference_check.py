#!/usr/bin/env python3
"""Our FLIP (tests/flip_cli) against NVIDIA's flip-evaluator on real render pairs.

For every pair, flip_cli computes
  flip    = LDR-FLIP of the Reinhard-tonemapped (v / (1 + v), negatives as 0),
            sRGB-encoded images, and
  hdrflip = HDR-FLIP of the linear images,
and dumps the float RGB it read; flip-evaluator then runs on exactly that data.
Means must agree within --tolerance (relative, default 1%).

Pairs: testdata/pairs/NAME_<N>spp.exr against NAME_ref.exr, a few scenegen
frames (sppN_00.exr against gt_a.exr) below testdata, and any given as
REFERENCE.exr:TEST.exr arguments. Fewer than --min-pairs pairs is a failure.
Exit 0 when all agree, 1 otherwise, 77 (skipped) when flip_evaluator is not
installed (pip install flip-evaluator).
"""
import argparse
import glob
import json
import os
import re
import subprocess
import sys
import time

try:
    import numpy as np
    import flip_evaluator
except ImportError as e:  # CTest reports this as skipped
    print(f"skipped: {e} (pip install flip-evaluator numpy)")
    sys.exit(77)


def discover_pairs(testdata, max_frames):
    """pairs/NAME_<N>spp.exr with NAME_ref.exr, and up to max_frames scenegen
    frames anywhere below testdata: sppN_00.exr with gt_a.exr in the same folder."""
    pairs = []
    for test in sorted(glob.glob(os.path.join(testdata, "pairs", "*_*spp.exr"))):
        match = re.match(r"(.*)_\d+spp\.exr$", test)
        reference = f"{match.group(1)}_ref.exr" if match else None
        if reference and os.path.exists(reference):
            pairs.append((reference, test))
    for reference in sorted(glob.glob(os.path.join(testdata, "**", "gt_a.exr"), recursive=True)):
        folder = os.path.dirname(reference)
        tests = sorted(glob.glob(os.path.join(folder, "spp*_00.exr")))
        if tests and max_frames > 0:
            pairs.append((reference, tests[0]))
            max_frames -= 1
    return pairs


def reinhard_srgb(linear):
    v = np.maximum(linear, 0).astype(np.float32)
    v = v / (np.float32(1) + v)
    encoded = np.where(v <= 0.0031308, v * np.float32(12.92),
                       np.float32(1.055) * np.power(v, np.float32(1 / 2.4)) - np.float32(0.055))
    return np.ascontiguousarray(encoded, dtype=np.float32)


def reference_flip(reference, test, mode, parameters):
    # flip_evaluator converts sRGB inputs in place, so it gets copies.
    start = time.perf_counter()
    error, _, used = flip_evaluator.evaluate(reference.copy(), test.copy(), mode,
                                             applyMagma=False, parameters=parameters)
    return float(np.mean(error, dtype=np.float64)), time.perf_counter() - start, used


def check_pair(cli, reference_path, test_path, root, work_dir, tolerance):
    relative = os.path.relpath(test_path, root)
    if relative.startswith(".."):
        relative = os.path.basename(test_path)
    name = os.path.splitext(relative)[0].replace(os.sep, "_")
    prefix = os.path.join(work_dir, name)
    run = subprocess.run([cli, reference_path, test_path, "--dump", prefix],
                         capture_output=True, text=True)
    if run.returncode != 0:
        print(f"FAIL {name}: flip_cli exited {run.returncode}: {run.stderr.strip()}")
        return False
    ours = json.loads(run.stdout)
    reference = np.load(prefix + ".reference.npy")
    test = np.load(prefix + ".test.npy")

    ldr, ldr_seconds, _ = reference_flip(reinhard_srgb(reference), reinhard_srgb(test), "LDR", {})
    # Heatmaps: entries may differ only where an error sits on a colormap bin edge.
    their_magma, _, _ = flip_evaluator.evaluate(reinhard_srgb(reference), reinhard_srgb(test), "LDR")
    magma_mismatch = np.mean(np.any(np.abs(np.load(prefix + ".flip_magma.npy") - their_magma) > 1e-6,
                                    axis=2))
    linear_ref = np.ascontiguousarray(np.maximum(reference, 0), dtype=np.float32)
    linear_test = np.ascontiguousarray(np.maximum(test, 0), dtype=np.float32)
    hdr, hdr_seconds, used = reference_flip(linear_ref, linear_test, "HDR", {})
    ok = magma_mismatch <= 0.001
    print(f"{'ok  ' if ok else 'FAIL'} {name:44s} magma   {magma_mismatch:.2e} of pixels differ "
          f"from flip-evaluator's heatmap")
    for metric, theirs, our_seconds, their_seconds in (
            ("flip", ldr, ours["flip_seconds"], ldr_seconds),
            ("hdrflip", hdr, ours["hdrflip_seconds"], hdr_seconds)):
        relative = abs(ours[metric] - theirs) / max(abs(theirs), 1e-9)
        good = relative <= tolerance
        ok &= good
        print(f"{'ok  ' if good else 'FAIL'} {name:44s} {metric:7s} ours {ours[metric]:.6f}  "
              f"flip-evaluator {theirs:.6f}  rel {relative:.2e}  "
              f"time ours {our_seconds:.3f}s ref {their_seconds:.3f}s")
    print(f"     {'':44s} {ours['width']}x{ours['height']}, exposures ours "
          f"[{ours['start_exposure']:.4f}, {ours['stop_exposure']:.4f}] x{ours['num_exposures']}, "
          f"reference [{used['startExposure']:.4f}, {used['stopExposure']:.4f}] "
          f"x{used['numExposures']}")
    return ok


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cli", required=True, help="path to the flip_cli executable")
    parser.add_argument("--testdata", help="folder with pairs/NAME_<N>spp.exr and NAME_ref.exr")
    parser.add_argument("--work-dir", required=True, help="where the dumped float data goes")
    parser.add_argument("--tolerance", type=float, default=0.01)
    parser.add_argument("--min-pairs", type=int, default=5)
    parser.add_argument("--max-frames", type=int, default=2,
                        help="at most this many scenegen frames (all of pairs/ are used)")
    parser.add_argument("pairs", nargs="*", help="REFERENCE.exr:TEST.exr")
    args = parser.parse_args()
    os.makedirs(args.work_dir, exist_ok=True)

    pairs = discover_pairs(args.testdata, args.max_frames) if args.testdata else []
    pairs += [tuple(p.split(":", 1)) for p in args.pairs]
    if len(pairs) < args.min_pairs:
        print(f"FAIL: {len(pairs)} render pairs found, at least {args.min_pairs} needed "
              f"(testdata/pairs/NAME_<N>spp.exr with NAME_ref.exr, or scenegen frames)")
        return 1
    root = args.testdata or os.getcwd()  # pair names are paths relative to this
    failures = sum(not check_pair(args.cli, r, t, root, args.work_dir, args.tolerance)
                   for r, t in pairs)
    print(f"{len(pairs) - failures} of {len(pairs)} pairs agree within {args.tolerance:.0%}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
