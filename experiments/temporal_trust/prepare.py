"""What the learned temporal trust is fitted on, from the animated scenes of
scenegen/animate.py: each scene's frames denoised alone, then the temporal
filter's view of every neighbour dumped beside the frame's independent render.

  python3 experiments/temporal_trust/prepare.py --data DATA/anim [--bin build/bin]

Per scene and input spp: SCENE/alone{spp}.NNNN.exr (dndenoise --temporal off --rgb-only: the result alone)
and SCENE/dump{spp}/ (temporal_refilter --dump-trust, with the rules' weights).
Existing outputs are kept, so the same command finishes what is missing.
"""

import argparse
import glob
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def run(cmd, log):
    with open(log, "a") as out:
        if subprocess.call(cmd, stdout=out, stderr=subprocess.STDOUT) != 0:
            sys.exit("prepare.py: failed (%s): %s" % (log, " ".join(cmd)))


def complete(scene, pattern, frames):
    return all(os.path.exists(os.path.join(scene, pattern % k)) for k in frames)


def prepare(scene, spp, args):
    frames = sorted(int(p.split(".")[-2]) for p in glob.glob(os.path.join(scene, "spp%d.*.exr" % spp)))
    if not frames or not complete(scene, "target.%04d.exr", frames):
        return False
    log = os.path.join(scene, "prepare.log")
    noisy, alone = os.path.join(scene, "spp%d.#.exr" % spp), os.path.join(scene, "alone%d.#.exr" % spp)
    if not complete(scene, "alone%d.%%04d.exr" % spp, frames):
        run([os.path.join(args.bin, "dndenoise"), "--model", args.model, "--temporal", "off", "--float", "--rgb-only",
             "--threads", str(args.threads), noisy, "-o", alone], log)
    dump = os.path.join(scene, "dump%d" % spp)
    if not complete(dump, "%04d.scale.npy", frames):
        run([os.path.join(args.bin, "temporal_refilter"), noisy, alone, "-o",
             os.path.join(scene, "rules%d.#.exr" % spp), "--dump-trust", dump,
             "--target", os.path.join(scene, "target.#.exr")], log)
    return True


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="scenegen/animate.py's --out")
    ap.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    ap.add_argument("--model", default=os.path.join(ROOT, "models", "default.dnm"))
    ap.add_argument("--spp", default="4,16")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    done = 0
    for scene in sorted(glob.glob(os.path.join(args.data, "scene_*"))):
        for spp in (int(v) for v in args.spp.split(",")):
            done += prepare(scene, spp, args)
    print("prepare.py: %d scene renders ready in %s" % (done, args.data))


if __name__ == "__main__":
    main()
