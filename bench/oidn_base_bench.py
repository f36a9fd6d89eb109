#!/usr/bin/env python3
"""The pretrained base in dndenoise against OIDN itself, in one run: seconds
per megapixel at 1920x1080 (and any other --sizes), median of --repeats runs
each, interleaved, with the ratio; peak resident memory of dndenoise.

  oidn_base_bench.py --bin build/bin --model models/oidn.dnm [--sizes 1920x1080]
                     [--repeats 5] [--threads 2] [--prefilter [--light-paths]]

OIDN runs as `oidnBenchmark -r RT.hdr_alb_nrm.WxH` from the pyoidn wheel (its
own synthetic buffers, colour + albedo + normal, in memory: no file I/O), and
dndenoise with `--prefilter off`. With --prefilter both run OIDN's prefilter
mode: dndenoise its default, OIDN through pyoidn (the benchmark has no entry
for the albedo and normal filters) on random buffers of the frame's size in
memory, timing the execution of its albedo and normal filters (balanced
quality: the default-size networks, as dndenoise) and its colour filter with
cleanAux (default quality: the large network). --light-paths lets dndenoise
also split off the diffuse part (its default on renders with Cycles' light
passes, which the example has: three more networks); OIDN stays in its
prefilter mode, which has no such split.
dndenoise runs on the shipped example resized to the same size with oiiotool
(every layer kept) and `-n REPEATS`, whose timing line excludes reading,
writing and loading the model: the same work, the network and its pre- and
post-processing, is timed for both.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
EXAMPLE = os.path.join(HERE, "..", "testdata", "example", "scene000201_4spp.exr")


def oidn_dir():
    out = subprocess.run([sys.executable, "-c", "import os, pyoidn; print(os.path.dirname(pyoidn.__file__))"],
                         capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit("oidn_base_bench: pyoidn is not installed (scripts/install.sh installs it)")
    return os.path.join(out.stdout.strip(), "oidn")


def oidn_seconds(size, repeats, threads, prefilter):
    return prefilter_seconds(size, repeats, threads) if prefilter else benchmark_seconds(size, repeats, threads)


def prefilter_seconds(size, repeats, threads):
    """Median over repeats of OIDN's prefilter mode: albedo, normal, then colour with cleanAux."""
    import time
    import numpy as np
    import pyoidn
    from pyoidn.filter import OIDN_FORMAT_FLOAT3, OIDN_QUALITY_BALANCED, OIDN_QUALITY_DEFAULT
    w, h = (int(v) for v in size.split("x"))
    rng = np.random.default_rng(0)
    color, albedo = rng.random((h, w, 3), dtype=np.float32), rng.random((h, w, 3), dtype=np.float32)
    normal = rng.random((h, w, 3), dtype=np.float32) * 2 - 1
    device = pyoidn.Device()
    device.set_int("numThreads", threads)
    device.commit()
    filters, outputs = [], []  # pyoidn keeps no reference to the arrays it is given
    for images, quality, clean in (({"albedo": albedo}, OIDN_QUALITY_BALANCED, False),
                                   ({"normal": normal}, OIDN_QUALITY_BALANCED, False),
                                   ({"color": color, "albedo": albedo, "normal": normal}, OIDN_QUALITY_DEFAULT,
                                    True)):
        f = pyoidn.Filter(device, "RT")
        f.set_quality(quality)
        f.set_bool("hdr", "color" in images)
        f.set_bool("cleanAux", clean)
        outputs.append(np.empty_like(color))
        for name, image in list(images.items()) + [("output", outputs[-1])]:
            f.set_image(name, image, OIDN_FORMAT_FLOAT3)
        f.commit()
        f.execute()  # warm-up, as oidnBenchmark
        filters.append(f)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for f in filters:
            f.execute()
        times.append(time.perf_counter() - start)
    return sorted(times)[len(times) // 2]


def benchmark_seconds(size, repeats, threads):
    base = oidn_dir()
    env = dict(os.environ, LD_LIBRARY_PATH=os.path.join(base, "lib"))
    cmd = [os.path.join(base, "bin", "oidnBenchmark"), "-r", f"RT.hdr_alb_nrm.{size}", "--threads", str(threads),
           "-n", str(repeats)]
    out = subprocess.run(cmd, capture_output=True, text=True, env=env)
    m = re.search(r"([\d.]+) msec/image", out.stdout + out.stderr)
    if out.returncode != 0 or not m:
        sys.exit(f"oidn_base_bench: {' '.join(cmd)} failed:\n{out.stdout}{out.stderr}")
    return float(m.group(1)) / 1000.0


def dndenoise_run(binary, model, frame, out, repeats, threads, prefilter, light_paths, flags):
    cmd = ["/usr/bin/time", "-v", os.path.join(binary, "dndenoise"), "--model", model, "--rgb-only",
           "--prefilter", "on" if prefilter else "off", "--light-paths", "on" if light_paths else "off",
           "--threads", str(threads), "-n", str(repeats), *flags.split(),
           frame, "-o", out]
    res = subprocess.run(cmd, capture_output=True, text=True)
    m = re.search(r"([\d.]+) s \(median of \d+\)", res.stderr)
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", res.stderr)
    if res.returncode != 0 or not m:
        sys.exit(f"oidn_base_bench: {' '.join(cmd)} failed:\n{res.stderr}")
    return float(m.group(1)), int(rss.group(1)) / 1e6


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True)
    ap.add_argument("--model", required=True)
    ap.add_argument("--sizes", default="1920x1080")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds of OIDN and dndenoise")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--prefilter", action="store_true", help="both in OIDN's prefilter mode")
    ap.add_argument("--light-paths", action="store_true",
                    help="with --prefilter: dndenoise also splits off the diffuse part")
    ap.add_argument("--flags", default="", help="more dndenoise flags, e.g. '--control on'")
    args = ap.parse_args()
    if args.light_paths and not args.prefilter:
        ap.error("--light-paths needs --prefilter")
    mode = ("prefilter mode, dndenoise with the light-path split; " if args.light_paths
            else "prefilter mode; " if args.prefilter else "")
    flags = f"dndenoise {args.flags}; " if args.flags else ""
    print(f"model {args.model}; {mode}{flags}{args.threads} threads; median of {args.repeats} runs per round, "
          f"{args.rounds} rounds alternating")
    print(f"{'frame':>10} {'OIDN s/MPix':>11} {'ours s/MPix':>11} {'ours/OIDN':>9} {'ours peak RSS GB':>16}")
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes.split(","):
            w, h = (int(v) for v in size.split("x"))
            mpix = w * h / 1e6
            frame = os.path.join(tmp, f"frame_{size}.exr")
            subprocess.run(["oiiotool", EXAMPLE, "--resize", size, "-o", frame], check=True)
            oidn, ours, rss = [], [], 0.0
            for _ in range(args.rounds):
                oidn.append(oidn_seconds(size, args.repeats, args.threads, args.prefilter) / mpix)
                seconds, peak = dndenoise_run(args.bin, args.model, frame, os.path.join(tmp, "out.exr"),
                                              args.repeats, args.threads, args.prefilter, args.light_paths,
                                              args.flags)
                ours.append(seconds / mpix)
                rss = max(rss, peak)
            ratios = sorted(o / b for o, b in zip(ours, oidn))
            o_med, b_med = sorted(ours)[len(ours) // 2], sorted(oidn)[len(oidn) // 2]
            print(f"{size:>10} {b_med:>11.3f} {o_med:>11.3f} {ratios[len(ratios) // 2]:>9.2f} {rss:>16.2f}")


if __name__ == "__main__":
    main()
