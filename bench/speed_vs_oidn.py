#!/usr/bin/env python3
"""dndenoise against Intel OIDN 2.5.1 (pyoidn), whole process per frame, in one
run: every command once per round, the rounds interleaved, then the median wall,
CPU (user + system) and system seconds and the peak resident memory of each,
and the ratio of the median walls to OIDN's two modes:

  OIDN usual     experiments/oidn_denoise.py: colour + noisy albedo + normal, one network
  OIDN prefilter experiments/oidn_denoise.py --prefilter: albedo and normal
                 filters (balanced), then the colour with cleanAux (the large network)

against dndenoise's default and the settings given by --modes (each a name and
dndenoise flags; NAME=VALUE words among them go into its environment). Every process reads the frame, denoises and writes the
result (dndenoise with --rgb-only, as OIDN's runner writes RGB; the mode
`all layers` writes the result beside every input layer, dndenoise's default
output, to show what that costs), with the same --threads. Times come from os.wait4 on each child, not from the tools' own lines.

  speed_vs_oidn.py --bin build/bin [--model models/default.dnm] [--size 1920x1080]
                   [--rounds 3] [--threads 2] [--modes NAME=FLAGS;...] [--only NAME,...]

The frame is the shipped Cycles example (57 layers, with the diffuse light
passes) tiled to --size, so that its noise stays independent per pixel; with
--resize it is resized with oiiotool instead (interpolated: correlated noise,
which opens dndenoise's correlated-noise gate). The example is 256x256: a tiled
frame repeats its content, which the timing does not mind.
"""
import argparse
import os
import shlex
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
EXAMPLE = os.path.join(ROOT, "testdata", "example", "scene000201_4spp.exr")
OIDN_RUNNER = os.path.join(ROOT, "experiments", "oidn_denoise.py")

DEFAULT_MODES = ("high=-q high;high bf16=-q high --precision bf16;balanced (default)=;"
                 "all layers=--all-layers;"
                 "balanced bf16=--precision bf16;fast=-q fast;fast bf16=-q fast --precision bf16;"
                 "control on=--control on;control on bf16=--control on --precision bf16")


def tiled_frame(path, width, height):
    """The example repeated to width x height, every layer and its header kept."""
    import numpy as np
    import OpenEXR
    with OpenEXR.File(EXAMPLE, separate_channels=True) as f:
        header = dict(f.header())
        channels = {n: c.pixels for n, c in f.channels().items()}
    tiled = {}
    for name, pixels in channels.items():
        reps = (-(-height // pixels.shape[0]), -(-width // pixels.shape[1]))
        tiled[name] = np.ascontiguousarray(np.tile(pixels, reps)[:height, :width])
    derived = ("dataWindow", "displayWindow", "channels", "chunkCount", "lineOrder")
    header = {k: v for k, v in header.items() if k not in derived}
    header["compression"] = OpenEXR.ZIP_COMPRESSION
    with OpenEXR.File(header, tiled) as f:
        f.write(path)


def run_child(cmd, env, log):
    """Wall, user, system seconds and peak RSS (GB) of one child process."""
    with open(log, "w") as out:
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=dict(os.environ, **env))
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        with open(log) as f:
            sys.exit(f"speed_vs_oidn: {' '.join(map(shlex.quote, cmd))} failed:\n{f.read()[-3000:]}")
    return {"wall": wall, "user": usage.ru_utime, "sys": usage.ru_stime, "rss": usage.ru_maxrss / 1e6}


def median(values):
    s = sorted(values)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True, help="folder with dndenoise")
    ap.add_argument("--model", default=os.path.join(ROOT, "models", "default.dnm"))
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--modes", default=DEFAULT_MODES,
                    help="dndenoise settings, 'NAME=FLAGS' separated by ';' (default: %(default)s)")
    ap.add_argument("--only", default="", help="comma-separated subset of the names, OIDN's included")
    ap.add_argument("--resize", action="store_true", help="resize the example with oiiotool, not tile it")
    ap.add_argument("--frame", help="time this EXR instead of the example")
    ap.add_argument("--keep", help="folder to keep the frame, outputs and logs in")
    args = ap.parse_args()

    commands = {
        "OIDN usual": ({}, [sys.executable, OIDN_RUNNER, "--threads", str(args.threads)]),
        "OIDN prefilter": ({}, [sys.executable, OIDN_RUNNER, "--threads", str(args.threads), "--prefilter"]),
    }
    dndenoise = os.path.join(args.bin, "dndenoise")
    for spec in args.modes.split(";"):
        name, _, flags = spec.partition("=")
        words = shlex.split(flags)
        env = dict(w.split("=", 1) for w in words if "=" in w and not w.startswith("-"))
        flags = [w for w in words if not ("=" in w and not w.startswith("-"))]
        # --all-layers (the bench's, not dndenoise's): the result written beside every
        # input layer, as dndenoise does by default, instead of RGB alone as OIDN's runner.
        output = [] if "--all-layers" in flags else ["--rgb-only"]
        flags = [w for w in flags if w != "--all-layers"]
        commands[name.strip()] = (env, [dndenoise, "--model", args.model, "--threads", str(args.threads),
                                        *output, *flags])
    if args.only:
        wanted = [n.strip() for n in args.only.split(",")]
        unknown = [n for n in wanted if n not in commands]
        if unknown:
            ap.error(f"--only: unknown {', '.join(unknown)} (known: {', '.join(commands)})")
        commands = {n: c for n, c in commands.items() if n in wanted}

    tmp = tempfile.TemporaryDirectory()
    work = args.keep or tmp.name
    os.makedirs(work, exist_ok=True)
    w, h = (int(v) for v in args.size.split("x"))
    frame = args.frame
    if not frame:
        frame = os.path.join(work, f"frame_{args.size}{'_resized' if args.resize else ''}.exr")
        if args.resize:
            subprocess.run(["oiiotool", EXAMPLE, "--resize", args.size, "-o", frame], check=True)
        else:
            tiled_frame(frame, w, h)
    # Paths as the repository names them, so that a log names no folder of one machine.
    shown = frame if args.frame else os.path.basename(frame)
    model = os.path.relpath(os.path.realpath(args.model), ROOT)
    print(f"{shown}; {args.threads} threads; {args.rounds} rounds, each command once per round, in turn; "
          f"model {model}")
    results = {name: [] for name in commands}
    for r in range(args.rounds):
        for name, (env, cmd) in commands.items():
            slug = name.replace(" ", "_")
            out = os.path.join(work, f"out_{slug}.exr")
            results[name].append(run_child(cmd + [frame, "-o", out], env, os.path.join(work, f"log_{slug}_{r}.txt")))
            res = results[name][-1]
            print(f"  round {r + 1} {name:<16} {res['wall']:7.1f} s wall {res['user'] + res['sys']:7.1f} s cpu "
                  f"{res['sys']:5.1f} s sys {res['rss']:5.2f} GB", flush=True)

    print(f"\n{args.size}, medians of {args.rounds} (the machine's load is in every row alike):")
    print("ratios: wall (cpu) against OIDN's usual call and its prefilter mode; on a busy machine the CPU "
          "ratio is the steadier one")
    print(f"{'command':<16} {'wall s':>7} {'cpu s':>7} {'sys s':>6} {'peak GB':>7} "
          f"{'/ OIDN usual':>15} {'/ OIDN prefilter':>17}")
    walls = {n: median([x["wall"] for x in rs]) for n, rs in results.items()}
    cpus = {n: median([x["user"] + x["sys"] for x in rs]) for n, rs in results.items()}
    for name, rs in results.items():
        ratios = [f"{walls[name] / walls[o]:.2f}x ({cpus[name] / cpus[o]:.2f}x)" if o in walls else "-"
                  for o in ("OIDN usual", "OIDN prefilter")]
        print(f"{name:<16} {walls[name]:7.1f} {cpus[name]:7.1f} {median([x['sys'] for x in rs]):6.1f} "
              f"{max(x['rss'] for x in rs):7.2f} {ratios[0]:>15} {ratios[1]:>17}")


if __name__ == "__main__":
    main()
