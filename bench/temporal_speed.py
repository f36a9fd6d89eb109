#!/usr/bin/env python3
"""Whole-process time and peak memory of dndenoise on a 1080p frame sequence:
--temporal off (every frame alone), filter (the results averaged) and on (the
default: also the noisy renders accumulated and denoised again), against OIDN's
prefilter mode per frame (experiments/oidn_denoise.py --prefilter) in the same
run. The sequence is a small shot's frames tiled to about 1920x1080, every
channel kept (motion vectors too: they are in pixels), so the networks and the
filter see real buffers.

  temporal_speed.py --bin build/bin --shot /work/data/shots/room_dolly [--spp 4]
                    [--frames 6] [--tiles 15x11] [--rounds 1] [--threads 2] [--no-oidn]
                    [--passes] [--modes off on]

--passes: the same with the light passes (dndenoise --passes, a multilayer
result; the shot must have them): frame by frame, and on the sequence with the
light passes filtered over time (--temporal filter and on).

One process per setting, the settings interleaved round by round; prints wall
and CPU seconds and peak RSS per run, and each setting's median wall time over
the rounds as a ratio of --temporal off's.
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "experiments"))
from exrutil import read_channels, write_atomic  # noqa: E402


def tile_shot(shot, spp, frames, tiles, out):
    """Frames 1..frames of SHOT/spp<N>.<frame>.exr tiled (columns, rows) into OUT."""
    for frame in range(1, frames + 1):
        channels, header = read_channels(os.path.join(shot, f"spp{spp}.{frame:04d}.exr"))
        tiled = {name: np.tile(pixels, (tiles[1], tiles[0])) for name, pixels in channels.items()}
        write_atomic(os.path.join(out, f"spp{spp}.{frame:04d}.exr"), tiled, header)


def timed(cmd):
    result = subprocess.run(["/usr/bin/time", "-f", "TIME %e %U %S %M"] + cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"temporal_speed: {' '.join(cmd)} failed:\n{result.stderr}")
    wall, user, system, rss = re.search(r"TIME ([\d.]+) ([\d.]+) ([\d.]+) (\d+)", result.stderr).groups()
    return float(wall), float(user) + float(system), int(rss) / 1e6


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True)
    ap.add_argument("--shot", required=True, help="a folder of spp<N>.<frame>.exr with motion vectors")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--tiles", default="15x11", help="columns x rows (128x96 frames: 1920x1056)")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-oidn", action="store_true", help="leave out OIDN's prefilter mode")
    ap.add_argument("--passes", action="store_true", help="with --passes (no OIDN)")
    ap.add_argument("--modes", nargs="+", default=["off", "filter", "on"], choices=["off", "filter", "on"],
                    help="the --temporal settings run (off is the baseline)")
    args = ap.parse_args()
    tiles = tuple(int(v) for v in args.tiles.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        tile_shot(args.shot, args.spp, args.frames, tiles, tmp)
        frames = [os.path.join(tmp, f"spp{args.spp}.{f:04d}.exr") for f in range(1, args.frames + 1)]
        size = read_channels(frames[0])[0]
        height, width = next(iter(size.values())).shape
        print(f"{args.frames} frames of {os.path.basename(os.path.normpath(args.shot))} at {width}x{height}, "
              f"{args.threads} threads, {os.cpu_count()} cores")
        dndenoise = os.path.join(args.bin, "dndenoise")
        pattern = os.path.join(tmp, f"spp{args.spp}.#.exr")
        output = ["--passes"] if args.passes else ["--rgb-only"]
        runs = {f"--temporal {mode}": [dndenoise, pattern, "-o", os.path.join(tmp, f"{mode}.#.exr"),
                                       *output, "--temporal", mode, "--threads", str(args.threads)]
                for mode in dict.fromkeys(["off"] + args.modes)}
        if not args.no_oidn and not args.passes:
            runs["OIDN prefilter"] = [sys.executable, os.path.join(HERE, "..", "experiments", "oidn_denoise.py"),
                                      *frames, "-o", os.path.join(tmp, "oidn") + "/", "--prefilter",
                                      "--threads", str(args.threads)]
        walls = {name: [] for name in runs}
        print(f"{'run':<18} {'round':>5} {'wall s':>8} {'CPU s':>8} {'peak GB':>8}")
        for r in range(args.rounds):
            for name, cmd in runs.items():
                wall, cpu, rss = timed(cmd)
                walls[name].append(wall)
                print(f"{name:<18} {r + 1:>5} {wall:>8.1f} {cpu:>8.1f} {rss:>8.2f}", flush=True)
        base = statistics.median(walls["--temporal off"])
        print("median wall time over the rounds, against --temporal off:")
        for name, values in walls.items():
            print(f"  {name:<18} {statistics.median(values):8.1f} s  {statistics.median(values) / base:.2f}x")


if __name__ == "__main__":
    main()
