#!/usr/bin/env python3
"""Wall-clock speed of one method on this machine.

  speed.py --args-file F --small S.exr --big B.exr --repeats R --out OUT.json -- COMMAND...
      COMMAND is a shell command with the placeholders {args} (the contents of F),
      {in} and {out}. It runs once on S as a warm-up, then R times on S and R times
      on B, alternating. The median times give the cost of a megapixel,
      (t_big - t_small) / (MP_big - MP_small), free of the fixed cost of starting
      the process and loading the model, which is reported separately
      (t_small - MP_small * seconds_per_MP). The load average before and after is
      kept: the machine may be shared.
"""

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time

from exrutil import ExrError, fail, read_channels


def megapixels(path):
    channels, _ = read_channels(path)
    height, width = next(iter(channels.values())).shape[:2]
    return width * height / 1e6, width, height


def run_once(command, args, source, folder):
    target = os.path.join(folder, "out.exr")
    text = command.replace("{args}", args).replace("{in}", shlex.quote(source)).replace("{out}", target)
    start = time.perf_counter()
    done = subprocess.run(["bash", "-c", text], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0 or not os.path.exists(target):
        fail(f"speed: `{text}` failed ({done.returncode}): {done.stderr.strip()[-400:]}")
    os.remove(target)
    return seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--args-file", required=True)
    parser.add_argument("--small", required=True)
    parser.add_argument("--big", required=True)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", required=True)
    parser.add_argument("command", nargs="+")
    options = parser.parse_args()
    command = " ".join(options.command)
    with open(options.args_file) as f:
        args = f.read().strip()
    try:
        small_mp, small_w, small_h = megapixels(options.small)
        big_mp, big_w, big_h = megapixels(options.big)
    except ExrError as error:
        fail(f"speed: {error}")
    load_before = os.getloadavg()[0]
    small, big = [], []
    with tempfile.TemporaryDirectory(prefix="speed", dir=os.path.dirname(os.path.abspath(options.out))) as folder:
        run_once(command, args, options.small, folder)
        for _ in range(options.repeats):
            small.append(run_once(command, args, options.small, folder))
            big.append(run_once(command, args, options.big, folder))
    t_small, t_big = statistics.median(small), statistics.median(big)
    per_mp = (t_big - t_small) / (big_mp - small_mp)
    result = {
        "command": command.replace("{args}", args), "repeats": options.repeats,
        "small": {"file": options.small, "width": small_w, "height": small_h, "seconds": small},
        "big": {"file": options.big, "width": big_w, "height": big_h, "seconds": big},
        "seconds_per_megapixel": per_mp, "fixed_seconds": t_small - small_mp * per_mp,
        "big_seconds_per_megapixel_total": t_big / big_mp,
        "load_average": [load_before, os.getloadavg()[0]], "nproc": os.cpu_count(),
    }
    tmp = f"{options.out}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        json.dump(result, f, indent=1)
    os.replace(tmp, options.out)


if __name__ == "__main__":
    sys.exit(main())
