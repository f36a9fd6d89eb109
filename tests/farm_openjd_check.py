#!/usr/bin/env python3
"""The farm template (farm/denoise.openjd.yaml) through the Open Job
Description CLI and the real dndenoise: `openjd check` accepts it, `openjd run`
denoises frames 1-3 of testdata/sequence in two chunks (1-2 and 3), and every
channel of every part of the three frames is bit-identical to one dndenoise
run over 1-3 (each chunk reads its neighbours beyond its edges itself). A
chunk over frames that do not exist fails with dndenoise's one line.

  farm_openjd_check.py --venv DIR --dndenoise BIN --source DIR --work-dir DIR
"""
import argparse
import os
import shutil
import sys

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cli_checks import check, run, summary  # noqa: E402

FRAMES = (1, 2, 3)


def pixels(path):
    """Every channel of every part: the pixel data, without the headers (whose
    dn:command differs between the runs)."""
    with OpenEXR.File(path, separate_channels=True) as f:
        return {(part.name(), name): channel.pixels.copy()
                for part in f.parts for name, channel in part.channels.items()}


def main():
    ap = argparse.ArgumentParser()
    for a in ("--venv", "--dndenoise", "--source", "--work-dir"):
        ap.add_argument(a, required=True)
    args = ap.parse_args()
    work = os.path.abspath(args.work_dir)
    shutil.rmtree(work, ignore_errors=True)
    for folder in ("chunks", "whole"):
        os.makedirs(os.path.join(work, folder))
    openjd = os.path.join(args.venv, "bin", "openjd")
    if not os.path.exists(openjd):
        sys.exit(f"FAIL: no openjd in {args.venv} (scripts/install.sh puts it there; DN_BPY_VENV)")
    template = os.path.join(args.source, "farm", "denoise.openjd.yaml")
    shot = os.path.join(args.source, "testdata", "sequence", "spp4.#.exr")
    dndenoise = os.path.abspath(args.dndenoise)

    out = run([openjd, "check", template])
    check("openjd check accepts the template", out.returncode == 0, out.stdout + out.stderr)

    # Quality fast and a window of 2 keep it quick; the chunking is under test.
    params = [f"InputPattern={shot}", f"Dndenoise={dndenoise}", "Quality=fast", "Window=2", "Threads=2"]
    job = [openjd, "run", template] + [a for p in params for a in ("-p", p)]
    out = run(job + ["-p", f"OutputPattern={os.path.join(work, 'chunks', 'den.#.exr')}",
                     "-p", "Frames=1-3", "-p", "ChunkSize=2"])
    log = out.stdout + out.stderr
    check("openjd run: two chunks, frames 1-2 and 3", out.returncode == 0 and "Chunks run: 2" in log and
          "denoising frames 1-2" in log and "denoising frames 3-3" in log, log[-3000:])

    out = run([dndenoise, shot, "-o", os.path.join(work, "whole", "den.#.exr"), "--frames", "1-3",
               "-q", "fast", "--window", "2", "--threads", "2"])
    check("one dndenoise run over 1-3", out.returncode == 0, out.stderr)
    for n in FRAMES:
        name = f"den.{n:04d}.exr"
        chunked, whole = (pixels(os.path.join(work, f, name)) for f in ("chunks", "whole"))
        check(f"frame {n}: the chunks' pixels are bit-identical to one run's ({len(whole)} channels)",
              chunked.keys() == whole.keys() and all(np.array_equal(chunked[k], whole[k]) for k in whole))

    out = run(job + ["-p", f"OutputPattern={os.path.join(work, 'missing', 'den.#.exr')}",
                     "-p", "Frames=7-8", "-p", "ChunkSize=2"])
    log = out.stdout + out.stderr
    check("a chunk of missing frames fails with dndenoise's line", out.returncode != 0 and
          "missing frame 7" in log, log[-3000:])
    return summary()


if __name__ == "__main__":
    sys.exit(main())
