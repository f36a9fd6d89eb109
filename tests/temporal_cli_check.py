#!/usr/bin/env python3
"""dndenoise on a sequence with motion vectors (testdata/sequence, made by
experiments/render_sequences.py --scene object): the neighbours are
used by default (--temporal on), their noisy renders accumulated and denoised
again unless --temporal filter, -v says per frame how much came from history
and over how many frames the render was accumulated, a frame's result does
not depend on how the shot was split into runs (bit-identical pixels), and a
sequence without motion vectors is denoised frame by frame with one line
saying so, as is a single frame of a sequence without its Vector pass (its
neighbours' chains stop at it), or a frame of another size than its
neighbours. The filter as tensor operations
(--temporal-filter tensors, on the CPU device) gives the CPU code's frames
within 1e-4 of the peak. Also dnmetrics on the sequences (per-frame rows, flicker).

  temporal_cli_check.py --dndenoise BIN --dnmetrics BIN --testdata DIR --work-dir DIR
"""

import argparse
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from exr_numpy import read_rgb  # noqa: E402

FRAMES = range(1, 7)


def run(cmd, expect=0):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != expect:
        sys.exit(f"FAIL: {' '.join(cmd)} exited {result.returncode}, expected {expect}\n{result.stderr}")
    return result


def check(condition, what):
    if not condition:
        sys.exit("FAIL: " + what)
    print("ok:", what)


def without_vectors(source, target):
    """The frame with its Vector pass left out (every other channel kept)."""
    frame = OpenEXR.File(source, separate_channels=True)
    kept = {name: c for name, c in frame.channels().items() if ".Vector." not in name}
    OpenEXR.File(frame.header(), kept).write(target)


def cropped(source, target, width, height):
    """The frame's top-left width x height pixels, every channel kept."""
    frame = OpenEXR.File(source, separate_channels=True)
    header = frame.header()
    corner = np.array([width - 1, height - 1], dtype=np.int32)
    header["dataWindow"] = header["displayWindow"] = (np.zeros(2, dtype=np.int32), corner)
    kept = {name: c.pixels[:height, :width].copy() for name, c in frame.channels().items()}
    OpenEXR.File(header, kept).write(target)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dndenoise", required=True)
    ap.add_argument("--dnmetrics", required=True)
    ap.add_argument("--testdata", required=True)
    ap.add_argument("--work-dir", required=True)
    args = ap.parse_args()
    work = args.work_dir
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    shot = os.path.join(args.testdata, "sequence", "spp4.#.exr")
    # The sequence logic, not the model, is under test: the base network alone keeps it fast.
    fast = ["--prefilter", "off", "--light-paths", "off", "--threads", "2"]
    base = [args.dndenoise, shot, "--rgb-only", "--temporal", "on", "--window", "2"] + fast

    whole = run(base + ["-o", os.path.join(work, "whole.#.exr"), "-v"])
    lines = [l for l in whole.stderr.splitlines() if "from history" in l]
    check(len(lines) == len(FRAMES), f"-v reports history for each of the {len(FRAMES)} frames")
    check("(4 neighbours" in lines[2], "a middle frame has two neighbours on each side")
    check("frame 1: " in lines[0] and "(4 neighbours" in lines[0] and "(4 neighbours" in lines[-1],
          "the first and last frames take as many, all on the side the shot goes on")
    check(all("accumulated over" in l for l in lines), "-v says over how many frames each render was accumulated")
    # Two runs, 1-3 and 4-6, write the same bits as one run over 1-6.
    run(base + ["-o", os.path.join(work, "split.#.exr"), "--frames", "1-3"])
    run(base + ["-o", os.path.join(work, "split.#.exr"), "--frames", "4-6"])
    same = all(np.array_equal(read_rgb(os.path.join(work, f"whole.{n:04d}.exr")),
                              read_rgb(os.path.join(work, f"split.{n:04d}.exr"))) for n in FRAMES)
    check(same, "frames 1-3 and 4-6 in two runs are bit-identical to 1-6 in one run")
    # A frame denoised again (-n, for timing) writes the same bits: the prefilter's
    # albedo and normal, which the history's second denoising reads, are kept for it.
    prefiltered = [args.dndenoise, shot, "--rgb-only", "--window", "2", "--threads", "2"]
    run(prefiltered + ["-o", os.path.join(work, "once.#.exr")])
    run(prefiltered + ["-o", os.path.join(work, "twice.#.exr"), "-n", "2"])
    same = all(np.array_equal(read_rgb(os.path.join(work, f"once.{n:04d}.exr")),
                              read_rgb(os.path.join(work, f"twice.{n:04d}.exr"))) for n in FRAMES)
    check(same, "-n 2 writes the same bits as one denoising, the prefilter mode's history too")

    # On by default wherever the frames carry motion: the same bits as --temporal on.
    plain = [args.dndenoise, shot, "--rgb-only"] + fast
    run(plain + ["-o", os.path.join(work, "default.#.exr")])
    run(plain + ["-o", os.path.join(work, "on.#.exr"), "--temporal", "on"])
    run(plain + ["-o", os.path.join(work, "alone.#.exr"), "--temporal", "off"])
    filtered = run(plain + ["-o", os.path.join(work, "filter.#.exr"), "--temporal", "filter", "-v"])
    run(plain + ["-o", os.path.join(work, "rules.#.exr"), "--temporal-trust", "rules"])
    run(plain + ["-o", os.path.join(work, "learned.#.exr"), "--temporal-trust", "learned"])
    # The filter as tensor operations (on the CPU device here; --device cuda's default),
    # against its per-pixel code, in float (half's rounding would hide or magnify the difference).
    run(plain + ["-o", os.path.join(work, "cpu.#.exr"), "--temporal-filter", "cpu"])
    for path in ("cpu", "tensors"):
        for trust in ("rules", "learned"):
            run(plain + ["-o", os.path.join(work, f"{path}_{trust}_float.#.exr"), "--float",
                         "--temporal-filter", path, "--temporal-trust", trust])
    check(not any("accumulated over" in l for l in filtered.stderr.splitlines()),
          "--temporal filter: no render accumulated")
    frames = {name: [read_rgb(os.path.join(work, f"{name}.{n:04d}.exr")) for n in FRAMES]
              for name in ("whole", "default", "on", "alone", "filter", "rules", "learned", "cpu",
                           "cpu_rules_float", "cpu_learned_float", "tensors_rules_float",
                           "tensors_learned_float")}
    check(all(not np.array_equal(a, b) for a, b in zip(frames["default"], frames["filter"])),
          "the default denoises the accumulated renders too (not the same as --temporal filter)")
    check(all(np.array_equal(a, b) for a, b in zip(frames["default"], frames["on"])),
          "the default uses the neighbours (= --temporal on)")
    check(all(np.array_equal(a, b) for a, b in zip(frames["default"], frames["rules"])),
          "the default weighs neighbours by the hand-set tests (= --temporal-trust rules)")
    check(any(not np.array_equal(a, b) for a, b in zip(frames["default"], frames["learned"])) and
          all(not np.array_equal(a, b) for a, b in zip(frames["learned"], frames["alone"])),
          "--temporal-trust learned: the model's network changes the weights, neighbours still used")
    check(all(np.array_equal(a, b) for a, b in zip(frames["default"], frames["cpu"])),
          "on the CPU the filter runs its per-pixel code by default (= --temporal-filter cpu)")
    for trust in ("rules", "learned"):
        worst = max(float(np.max(np.abs(a - b)) / max(1e-6, float(np.max(np.abs(b)))))
                    for a, b in zip(frames[f"tensors_{trust}_float"], frames[f"cpu_{trust}_float"]))
        print(f"--temporal-filter tensors against the CPU's code (--temporal-trust {trust}): "
              f"max |difference| {worst:.2e} of the peak")
        check(worst < 1e-4, f"--temporal-filter tensors gives the CPU code's frames within 1e-4 of the "
              f"peak (--temporal-trust {trust})")
    no_trust = os.path.join(os.path.dirname(os.path.abspath(args.testdata)), "models", "oidn.dnm")
    result = run(plain + ["-o", os.path.join(work, "bad.#.exr"), "--temporal-trust", "learned",
                          "--model", no_trust], expect=1)
    check(len(result.stderr.strip().splitlines()) == 1 and "carries no learned trust" in result.stderr,
          "--temporal-trust learned with a model without one: one line, exit 1")
    check(all(not np.array_equal(a, b) for a, b in zip(frames["default"], frames["alone"])) and
          all(not np.array_equal(a, b) for a, b in zip(frames["whole"], frames["alone"])),
          "the default and --window 2 give other results than --temporal off (each frame alone)")

    # No motion vectors: one line, frame by frame, the same pixels as --temporal off.
    still = os.path.join(args.testdata, "renderers", "blender5_hdri_4spp.exr")
    for n in (1, 2):
        shutil.copy(still, os.path.join(work, f"novec.{n:04d}.exr"))
    novec = run([args.dndenoise, os.path.join(work, "novec.#.exr"), "-o",
                 os.path.join(work, "novec_out.#.exr"), "--rgb-only"] + fast)
    notes = [l for l in novec.stderr.splitlines() if "frame by frame" in l]
    check(len(notes) == 1 and "no motion vectors" in notes[0], "no motion vectors: one line, frame by frame")

    # One frame without its Vector pass: denoised alone, one line saying why; its
    # neighbours' chains stop at it.
    gap = os.path.join(work, "gap")
    os.makedirs(gap)
    for n in FRAMES:
        source = os.path.join(args.testdata, "sequence", f"spp4.{n:04d}.exr")
        target = os.path.join(gap, f"spp4.{n:04d}.exr")
        without_vectors(source, target) if n == 3 else shutil.copy(source, target)
    result = run([args.dndenoise, os.path.join(gap, "spp4.#.exr"), "-o", os.path.join(work, "gap_out.#.exr"),
                  "--rgb-only", "--window", "2", "-v"] + fast)
    notes = [l for l in result.stderr.splitlines() if "no motion vectors" in l]
    check(len(notes) == 1 and "spp4.0003.exr" in notes[0] and "denoised alone" in notes[0]
          and "chains stop at it" in notes[0], "a frame without the Vector pass: one line saying why it is alone")
    history = [l for l in result.stderr.splitlines() if "from history" in l]
    check("(0 neighbours" in history[2] and "(1 neighbour" in history[1] and "(2 neighbours" in history[3],
          "its neighbours' chains stop at it (frame 2: frame 1 alone; frame 4: frames 5 and 6)")

    # One frame of another size: denoised alone, one line saying why; the
    # neighbours' chains stop at it, as at a frame without vectors.
    odd = os.path.join(work, "odd")
    os.makedirs(odd)
    for n in FRAMES:
        source = os.path.join(args.testdata, "sequence", f"spp4.{n:04d}.exr")
        target = os.path.join(odd, f"spp4.{n:04d}.exr")
        cropped(source, target, 24, 18) if n == 3 else shutil.copy(source, target)
    result = run([args.dndenoise, os.path.join(odd, "spp4.#.exr"), "-o", os.path.join(work, "odd_out.#.exr"),
                  "--rgb-only", "--window", "2", "-v"] + fast)
    notes = [l for l in result.stderr.splitlines() if "denoised alone" in l]
    check(len(notes) == 1 and "spp4.0003.exr" in notes[0] and "this frame is 24x18, its neighbours 48x36"
          in notes[0] and "chains stop at it" in notes[0], "a frame of another size: one line saying why it is alone")
    history = [l for l in result.stderr.splitlines() if "from history" in l]
    check("(0 neighbours" in history[2] and "(1 neighbour" in history[1] and "(2 neighbours" in history[3],
          "its neighbours' chains stop at it too")
    check(read_rgb(os.path.join(work, "odd_out.0003.exr")).shape[:2] == (18, 24),
          "the odd frame's output has its own size")

    for bad in (["--window", "0"], ["--temporal", "maybe"], ["--window", "9"],
                ["--temporal-trust", "maybe"]):
        result = run(base + ["-o", os.path.join(work, "bad.#.exr")] + bad, expect=1)
        check(len(result.stderr.strip().splitlines()) == 1, f"{' '.join(bad)}: one line, exit 1")
    check(not any(f.startswith("bad.") for f in os.listdir(work)), "no output after a bad argument")

    # dnmetrics on sequences: each frame a row, flicker from the second frame on;
    # with one shared reference, the flicker is the mean |R(x_t) - R(x_t-1)|.
    ref = os.path.join(work, "whole.0001.exr")
    result = run([args.dnmetrics, ref, os.path.join(work, "alone.#.exr"), "--format", "json",
                  "--metrics", "psnr"])
    rows = json.loads(result.stdout)["results"]
    check(len(rows) == len(FRAMES) and rows[0]["flicker"] == "nan", "dnmetrics: a row per frame, no flicker for the first")
    reinhard = [np.minimum(a / (1 + a), 1.0) for a in
                (np.clip(read_rgb(os.path.join(work, f"alone.{n:04d}.exr")), 0, None) for n in FRAMES)]
    expected = float(np.mean(np.abs(reinhard[2] - reinhard[1])))
    check(abs(rows[2]["flicker"] - expected) < 1e-5 * max(1.0, expected),
          f"dnmetrics flicker {rows[2]['flicker']:.6g} = numpy's {expected:.6g}")


if __name__ == "__main__":
    main()
