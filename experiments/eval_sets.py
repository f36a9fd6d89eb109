#!/usr/bin/env python3
"""Scores one denoising method on every evaluation set at once: the test split
of the Cycles data set, the user-style Blender scenes (sets A and B) and the
renders of other renderers (Blender 5, Mitsuba with box and with Gaussian
pixel filters), at 4, 16 and 64 spp. Mean L1, PSNR, SSIM and FLIP per set and
spp, as dnmetrics computes them; per-file metrics in WORK/<name>/metrics.json.

  eval_sets.py --name oidn --oidn                      OIDN 2 itself (pyoidn, colour + albedo + normal)
  eval_sets.py --name noisy                            the input
  eval_sets.py --name ctl -- --model /work/train/diff.dnm --sigmas 0.05,0.02   dndenoise with these flags
  eval_sets.py --table noisy oidn ctl                  a Markdown table of stored results

Sets (missing ones are skipped with a note):
  test     --test-split DIR: scene_*/frame_0 with 4-spp stacks (inputs by make_inputs.py, cached)
  user     --user DIR: <scene>_<N>spp.exr and <scene>_ref.exr (experiments/user_scenes.py)
  blender5, mitsuba_box, mitsuba_gauss   --evaldata DIR: <set>/<scene>/spp<N>.exr and ref.exr
                                          (experiments/render_evaldata.sh)
"""

import argparse
import glob
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SPPS = (4, 16, 64)
METRICS = ("l1", "psnr", "ssim", "flip")


def run(cmd):
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def test_pairs(split, work):
    pairs = []
    for scene in sorted(glob.glob(os.path.join(split, "scene_*"))):
        if not os.path.exists(os.path.join(scene, "frame_0", "meta.json")):
            continue  # still rendering
        name = os.path.basename(scene)
        inputs, refs = os.path.join(work, "test_in", name), os.path.join(work, "test_ref", name)
        if not all(os.path.exists(os.path.join(inputs, f"frame_0_spp{s}.exr")) for s in SPPS):
            run([sys.executable, os.path.join(HERE, "make_inputs.py"), "scene", scene, "--frames", "frame_0",
                 "--spps", *map(str, SPPS), "--inputs", inputs, "--refs", refs])
        for spp in SPPS:
            pairs.append(("test", name, spp, os.path.join(inputs, f"frame_0_spp{spp}.exr"),
                          os.path.join(refs, "frame_0.exr")))
    return pairs


def user_pairs(folder):
    pairs = []
    for ref in sorted(glob.glob(os.path.join(folder, "*_ref.exr"))):
        scene = os.path.basename(ref)[:-len("_ref.exr")]
        for spp in SPPS:
            source = os.path.join(folder, f"{scene}_{spp}spp.exr")
            if os.path.exists(source):
                pairs.append(("user", scene, spp, source, ref))
    return pairs


def evaldata_pairs(root):
    pairs = []
    for ref in sorted(glob.glob(os.path.join(root, "*", "*", "ref.exr"))):
        scene_dir = os.path.dirname(ref)
        group = os.path.basename(os.path.dirname(scene_dir))
        for spp in SPPS:
            source = os.path.join(scene_dir, f"spp{spp}.exr")
            if os.path.exists(source):
                pairs.append((group, os.path.basename(scene_dir), spp, source, ref))
    return pairs


def score(bin_dir, reference, result):
    out = subprocess.run([os.path.join(bin_dir, "dnmetrics"), "--format", "json", "--metrics",
                          ",".join(METRICS), reference, result], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)["results"][0]


def evaluate(args, extra):
    pairs = []
    if args.test_split and os.path.isdir(args.test_split):
        pairs += test_pairs(os.path.abspath(args.test_split), args.work)
    if args.user:
        for folder in args.user:
            pairs += user_pairs(folder)
    if args.evaldata and os.path.isdir(args.evaldata):
        pairs += evaldata_pairs(args.evaldata)
    if not pairs:
        sys.exit("eval_sets: no evaluation renders found (see --help)")
    out_dir = os.path.join(args.work, args.name)
    os.makedirs(out_dir, exist_ok=True)
    rows = []
    for group, scene, spp, source, reference in pairs:
        result = source
        if args.name != "noisy":
            result = os.path.join(out_dir, f"{group}_{scene}_spp{spp}.exr")
            if args.oidn:
                run([sys.executable, os.path.join(HERE, "oidn_denoise.py"), "--threads", str(args.threads),
                     source, "-o", result])
            else:
                run([os.path.join(args.bin, "dndenoise"), "--rgb-only", "--float", "--threads",
                     str(args.threads), *extra, source, "-o", result])
        m = score(args.bin, reference, result)
        rows.append({"set": group, "scene": scene, "spp": spp, **{k: m[k] for k in METRICS}})
        print(f"{args.name} {group}/{scene} spp{spp}: PSNR {m['psnr']:.2f} FLIP {m['flip']:.4f}", flush=True)
    with open(os.path.join(out_dir, "metrics.json"), "w") as f:
        json.dump({"name": args.name, "flags": extra, "rows": rows}, f, indent=1)


def table(args, names):
    results = {}
    for name in names:
        with open(os.path.join(args.work, name, "metrics.json")) as f:
            results[name] = {(r["set"], r["scene"], r["spp"]): r for r in json.load(f)["rows"]}
    keys = sorted(set.intersection(*(set(r) for r in results.values())))
    groups = sorted({(k[0], k[2]) for k in keys}, key=lambda g: (g[0], g[1]))
    print("| set | spp | frames | " + " | ".join(f"{n} PSNR / FLIP / L1" for n in names) + " |")
    print("|---|---|---|" + "---|" * len(names))
    for group, spp in groups:
        ks = [k for k in keys if k[0] == group and k[2] == spp]
        cells = []
        for n in names:
            mean = {m: sum(results[n][k][m] for k in ks) / len(ks) for m in METRICS}
            cells.append(f"{mean['psnr']:.2f} / {mean['flip']:.4f} / {mean['l1']:.4f}")
        print(f"| {group} | {spp} | {len(ks)} | " + " | ".join(cells) + " |")
    if len(names) >= 2:
        a, b = names[-1], names[-2]
        worst = min(keys, key=lambda k: results[a][k]["psnr"] - results[b][k]["psnr"])
        d = results[a][worst]["psnr"] - results[b][worst]["psnr"]
        print(f"\nlargest PSNR loss of {a} against {b}: {d:+.2f} dB on {worst[0]}/{worst[1]} spp{worst[2]}")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--name", help="name of the method (output subfolder)")
    p.add_argument("--oidn", action="store_true", help="run OIDN (pyoidn) instead of dndenoise")
    p.add_argument("--table", nargs="+", metavar="NAME", help="print a table of stored results")
    p.add_argument("--test-split", default="/work/data/scenes/test")
    p.add_argument("--user", nargs="*", default=["/work/agree/user"])
    p.add_argument("--evaldata", default="/work/evaldata")
    p.add_argument("--work", default="/work/eval")
    p.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    p.add_argument("--threads", type=int, default=2)
    args, extra = p.parse_known_args()
    if extra and extra[0] == "--":
        extra = extra[1:]
    if args.table:
        table(args, args.table)
    elif args.name:
        evaluate(args, extra)
    else:
        p.error("give --name (evaluate) or --table")


if __name__ == "__main__":
    main()
