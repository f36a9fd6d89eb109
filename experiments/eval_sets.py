#!/usr/bin/env python3
"""Scores one denoising method on every evaluation set at once: the test split
of the Cycles data set, the user-style Blender scenes (sets A and B) and the
renders of other renderers (Blender 5, Mitsuba with box and with Gaussian
pixel filters), at 4, 16 and 64 spp. Mean L1, PSNR, SSIM and FLIP per set and
spp, as dnmetrics computes them; per-file metrics in WORK/<name>/metrics.json.

  eval_sets.py --name oidn --oidn                      OIDN 2 itself (pyoidn, colour + albedo + normal)
  eval_sets.py --name oidn_alb --oidn -- --aux albedo  OIDN with colour + albedo (oidn_denoise.py flags)
  eval_sets.py --name isik --isik models/isik.pt       the Isik-style kernel network (dncleanse)
  eval_sets.py --name noisy                            the input
  eval_sets.py --name ctl -- --model /work/train/diff.dnm --sigmas 0.05,0.02   dndenoise with these flags
  eval_sets.py --name ctl --reuse -- ...               the same, keeping results already made (new renders only)
  eval_sets.py --table noisy oidn ctl                  a Markdown table of stored results
  eval_sets.py --compare oidn ctl                      per set, the frames where ctl beats oidn
  eval_sets.py --table noisy,oidn,ctl oidn_alb,ctl_alb one table per comma list
  eval_sets.py --table 'colour + albedo:oidn_alb,ctl_alb'   ... with a heading

Sets (missing ones are skipped with a note):
  test     --test-split DIR: scene_*/frame_0 with 4-spp stacks (inputs by make_inputs.py, cached)
  user     --user DIR: <scene>_<N>spp.exr and <scene>_ref.exr (experiments/user_scenes.py)
  blender5, mitsuba_box, mitsuba_gauss   --evaldata DIR: <set>/<scene>/spp<N>.exr and ref.exr
                                          (experiments/render_evaldata.sh)
"""

import argparse
import datetime
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
            if args.reuse and os.path.exists(result):
                pass
            elif args.oidn:
                run([sys.executable, os.path.join(HERE, "oidn_denoise.py"), "--threads", str(args.threads),
                     *extra, source, "-o", result])
            else:
                cmd = ([os.path.join(args.bin, "dncleanse"), source, "-o", result, "--model", args.isik,
                        "--rgb-only"] if args.isik else
                       [os.path.join(args.bin, "dndenoise"), "--rgb-only", "--float", "--threads",
                        str(args.threads), *extra, source, "-o", result])
                if args.skip_unusable:  # e.g. a model that needs passes the renderer did not write
                    out = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
                    if out.returncode == 1:
                        print(f"{args.name} {group}/{scene} spp{spp}: skipped: {out.stderr.strip()}",
                              flush=True)
                        continue
                    out.check_returncode()
                else:
                    run(cmd)
        m = score(args.bin, reference, result)
        rows.append({"set": group, "scene": scene, "spp": spp, **{k: m[k] for k in METRICS}})
        print(f"{args.name} {group}/{scene} spp{spp}: PSNR {m['psnr']:.2f} FLIP {m['flip']:.4f}", flush=True)
    with open(os.path.join(out_dir, "metrics.json"), "w") as f:
        json.dump({"name": args.name, "oidn": args.oidn, "isik": args.isik, "flags": extra, "rows": rows},
                  f, indent=1)


def load_results(work, names):
    """{name: {(set, scene, spp): metrics}} and {name: the command's arguments after --name}."""
    results, commands = {}, {}
    for name in names:
        with open(os.path.join(work, name, "metrics.json")) as f:
            data = json.load(f)
        results[name] = {(r["set"], r["scene"], r["spp"]): r for r in data["rows"]}
        commands[name] = (" --oidn" if data["oidn"] else "") + (
            " -- " + " ".join(data["flags"]) if data["flags"] else "")
    return results, commands


def table_lines(results, names):
    """Mean PSNR / FLIP / L1 per set and spp, and the largest loss of the last method against
    the one before it."""
    keys = sorted(set.intersection(*(set(r) for r in results.values())))
    groups = sorted({(k[0], k[2]) for k in keys})
    lines = ["| set | spp | frames | " + " | ".join(f"{n} PSNR / FLIP / L1" for n in names) + " |",
             "|---|---|---|" + "---|" * len(names)]
    for group, spp in groups:
        ks = [k for k in keys if k[0] == group and k[2] == spp]
        cells = []
        for n in names:
            mean = {m: sum(results[n][k][m] for k in ks) / len(ks) for m in METRICS}
            cells.append(f"{mean['psnr']:.2f} / {mean['flip']:.4f} / {mean['l1']:.4f}")
        lines.append(f"| {group} | {spp} | {len(ks)} | " + " | ".join(cells) + " |")
    if len(names) >= 2:
        a, b = names[-1], names[-2]
        worst = min(keys, key=lambda k: results[a][k]["psnr"] - results[b][k]["psnr"])
        d = results[a][worst]["psnr"] - results[b][worst]["psnr"]
        where = f"({worst[0]}/{worst[1]}, {worst[2]} spp)"
        lines += ["", f"{a} against {b}, frame by frame: "
                      + (f"worst {d:+.2f} dB PSNR {where}." if d < 0 else
                         f"never worse; the smallest gain {d:+.2f} dB PSNR {where}.")]
    return lines


def compare(args, a, b):
    """Per set, on how many frames `b` beats `a` (PSNR higher, FLIP lower), and the PSNR range."""
    results, _ = load_results(args.work, [a, b])
    keys = set(results[a]) & set(results[b])
    for group in sorted({k[0] for k in keys}):
        ks = [k for k in keys if k[0] == group]
        d = [results[b][k]["psnr"] - results[a][k]["psnr"] for k in ks]
        lower = sum(results[b][k]["flip"] < results[a][k]["flip"] for k in ks)
        print(f"{group}: {b} against {a}: PSNR higher on {sum(x > 0 for x in d)} of {len(ks)} "
              f"({min(d):+.2f} to {max(d):+.2f} dB), FLIP lower on {lower}")


def figure_lines(args, names, spec, folder, results_path):
    """A PNG strip: the input, OIDN's result, the last method's, the reference (one set/scene/spp)."""
    import numpy as np
    from PIL import Image
    from exrutil import read_color
    from page_sections import figure_tonemap

    where, spp = spec.rsplit(":", 1)
    group, scene = where.split("/")
    pair = next((p for p in evaldata_pairs(args.evaldata) if p[:3] == (group, scene, int(spp))), None)
    if pair is None:
        sys.exit(f"eval_sets: --figure {spec}: no such evaluation render in {args.evaldata}")
    source, reference = pair[3], pair[4]
    panels = [("noisy", source)]
    shown = [n for n in ("oidn", names[-1]) if n in names and n != "noisy"]
    panels += [(n, os.path.join(args.work, n, f"{group}_{scene}_spp{spp}.exr")) for n in shown]
    panels.append(("reference", reference))
    images = [figure_tonemap(read_color(path)) for _, path in panels]
    gap = np.full((images[0].shape[0], 4, 3), 255, np.uint8)
    strip = np.concatenate([x for image in images for x in (image, gap)][:-1], axis=1)
    os.makedirs(folder, exist_ok=True)
    png = os.path.join(folder, f"{group}_{scene}_spp{spp}.png")
    Image.fromarray(strip).save(png, optimize=True)
    relative = os.path.relpath(png, os.path.dirname(os.path.abspath(results_path)))
    return [f"{group}/{scene} at {spp} spp, left to right: " + " | ".join(n for n, _ in panels) + ":", "",
            f"![{group} {scene} {spp} spp]({relative})"]


from page_sections import SECTION_BEGIN, SECTION_END  # noqa: E402


def write_section(path, lines):
    """Puts `lines` between the markers in `path` (appended the first time); report.py keeps them."""
    old = open(path).read() if os.path.exists(path) else ""
    section = "\n".join([SECTION_BEGIN, *lines, SECTION_END])
    if SECTION_BEGIN in old:
        head, rest = old.split(SECTION_BEGIN, 1)
        new = head + section + rest.split(SECTION_END, 1)[1]
    else:
        new = old.rstrip() + "\n\n" + section + "\n"
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(new)
    os.replace(tmp, path)


def table(args, specs):
    """One table of the methods given; NAME,NAME,... arguments make one table each, and
    'TITLE:NAME,NAME' gives that table a heading."""
    split = [spec.rsplit(":", 1) if ":" in spec else ["", spec] for spec in specs]
    if any("," in spec for _, spec in split):
        tables = [(title, spec.split(",")) for title, spec in split]
    else:
        tables = [("", [spec for _, spec in split])]
    names = list(dict.fromkeys(n for _, t in tables for n in t))
    results, commands = load_results(args.work, names)
    lines = []
    for title, t in tables:
        lines += ([""] if lines else []) + ([f"### {title}", ""] if title else [])
        lines += table_lines({n: results[n] for n in t}, t)
    if not args.results:
        print("\n".join(lines))
        return
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    section = ["## Every evaluation set: other renderers, buffer sets and splatted noise", "",
               f"Generated by `experiments/eval_sets.py` on {datetime.date.today()} at commit `{commit}`; "
               "`report.py` keeps this section. Each method was scored with",
               "", "```sh"]
    section += [f"python3 experiments/eval_sets.py --name {n}{commands[n]}" for n in names]
    quoted = [f"'{spec}'" if " " in spec else spec for spec in specs]
    section += [f"python3 experiments/eval_sets.py --table {' '.join(quoted)} --results docs/RESULTS.md"
                + "".join(f" --figure {f}" for f in args.figure), "```", "",
                "Sets: `test`, the Cycles 3.4 test split; `user`, the hand-built Blender scenes "
                "(experiments/user_scenes.py); `blender5`, `mitsuba_box` (independent noise) and "
                "`mitsuba_gauss` (Mitsuba's default Gaussian pixel filter, which splats samples and "
                "correlates the noise) from experiments/render_evaldata.sh. Methods: `noisy`, the input; "
                "`oidn*`, OIDN 2.5.1 itself (pyoidn; colour + albedo + normal unless `--aux` says less; "
                "`oidn_pre`, its prefilter mode); `base`, `dndenoise --model models/oidn.dnm`; `default*`, "
                "`dndenoise` with no flags but `--buffers` (`default`: every buffer the file has). "
                "Means over frames; FLIP and L1 lower is better.", ""]
    section += lines
    for spec in args.figure:
        section += [""] + figure_lines(args, tables[-1][1], spec, os.path.join(ROOT, "docs", "results"),
                                       args.results)
    write_section(args.results, section)
    print(f"eval_sets: wrote the section into {args.results}")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--name", help="name of the method (output subfolder)")
    p.add_argument("--oidn", action="store_true", help="run OIDN (pyoidn) instead of dndenoise")
    p.add_argument("--isik", metavar="MODEL", help="run dncleanse with this kernel network instead")
    p.add_argument("--skip-unusable", action="store_true",
                   help="leave out the renders dndenoise refuses (exit 1) instead of stopping")
    p.add_argument("--table", nargs="+", metavar="NAME", help="print a table of stored results")
    p.add_argument("--compare", nargs=2, metavar=("A", "B"), help="count the frames where B beats A")
    p.add_argument("--results", help="with --table: write it into this file's eval_sets section instead")
    p.add_argument("--figure", action="append", default=[], metavar="SET/SCENE:SPP",
                   help="with --results: noisy | oidn | the last table's last method | reference "
                        "on this evaldata render")
    p.add_argument("--reuse", action="store_true",
                   help="keep results already in WORK/NAME (an earlier run on fewer sets, same flags)")
    p.add_argument("--test-split", default="/work/data/scenes/test")
    p.add_argument("--user", nargs="*", default=["/work/agree/user"])
    p.add_argument("--evaldata", default="/work/evaldata")
    p.add_argument("--work", default="/work/eval")
    p.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    p.add_argument("--threads", type=int, default=2)
    args, extra = p.parse_known_args()
    if extra and extra[0] == "--":
        extra = extra[1:]
    if args.compare:
        compare(args, *args.compare)
    elif args.table:
        table(args, args.table)
    elif args.name:
        evaluate(args, extra)
    else:
        p.error("give --name (evaluate), --table or --compare")


if __name__ == "__main__":
    main()
