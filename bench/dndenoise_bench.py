#!/usr/bin/env python3
"""dndenoise speed and memory on full-size frames: seconds per megapixel at the
model's default settings and per network step, and peak resident memory
(through tiling), at 1920x1080 and 3840x2160. The frames are the shipped
example render resized with oiiotool (every layer kept), so the network sees
real buffers.

  dndenoise_bench.py --bin build/bin --model models/default.dnm [--sizes 1920x1080,3840x2160]
                     [--maxmem 3000] [--steps N --skip S] [--all-layers]

The result is written with --rgb-only unless --all-layers asks for dndenoise's
default output (every input layer copied beside the result).
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
EXAMPLE = os.path.join(HERE, "..", "testdata", "example", "scene000201_4spp.exr")


def run_timed(cmd):
    out = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"dndenoise_bench: {' '.join(cmd)} failed:\n{out.stderr}")
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", out.stderr).group(1))
    line = re.search(r"(\d+) steps, [^\n]*?(\d+) tile\(s\) of (\d+) px, ([\d.]+) s \(median of (\d+)\), "
                     r"([\d.]+) s/MPix", out.stderr)
    if not line:
        sys.exit(f"dndenoise_bench: no timing line in the output of {' '.join(cmd)}:\n{out.stderr}")
    return {"steps": int(line.group(1)), "tiles": int(line.group(2)), "tile": int(line.group(3)),
            "seconds": float(line.group(4)), "s_per_mpix": float(line.group(6)), "rss_gb": rss_kb / 1e6}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--model", required=True)
    ap.add_argument("--sizes", default="1920x1080,3840x2160")
    ap.add_argument("--maxmem", default="3000")
    ap.add_argument("--steps")
    ap.add_argument("--skip")
    ap.add_argument("--all-layers", action="store_true", help="write every input layer, not --rgb-only")
    args = ap.parse_args()
    extra = (["--steps", args.steps] if args.steps else []) + (["--skip", args.skip] if args.skip else [])
    extra += [] if args.all_layers else ["--rgb-only"]
    output = "every input layer and the result" if args.all_layers else "--rgb-only"
    print(f"model {args.model}; --maxmem {args.maxmem} MB; {os.cpu_count()} cores; output {output}")
    print(f"{'frame':>10} {'steps':>5} {'tiles':>5} {'tile px':>7} {'seconds':>8} {'s/MPix':>8} "
          f"{'s/MPix/step':>11} {'peak RSS GB':>11}")
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes.split(","):
            frame = os.path.join(tmp, f"frame_{size}.exr")
            subprocess.run(["oiiotool", EXAMPLE, "--resize", size, "-o", frame], check=True)
            r = run_timed([os.path.join(args.bin, "dndenoise"), "--model", args.model, "--maxmem", args.maxmem,
                           "-v", frame, "-o", os.path.join(tmp, "out.exr")] + extra)
            print(f"{size:>10} {r['steps']:>5} {r['tiles']:>5} {r['tile']:>7} {r['seconds']:>8.1f} "
                  f"{r['s_per_mpix']:>8.2f} {r['s_per_mpix'] / r['steps']:>11.3f} {r['rss_gb']:>11.2f}")


if __name__ == "__main__":
    main()
