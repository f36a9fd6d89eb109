#!/usr/bin/env python3
"""Render the training data set: batches of scenes per Blender process (see docs/dataset.md).

  python3 scenegen/make_dataset.py --out DATA --scenes 300 --first-seed 0 \
      --res 128 --spp 4 --stacks 16 --gt-spp 256 --frames 2 --shard 0/4 --threads 2

Scenes are seeds first_seed .. first_seed+scenes-1; shard i/n takes every n-th
seed starting at the i-th, so n machines (or `make -j`) can share one output
folder. Finished frames are skipped, so an interrupted run resumes where it
stopped. manifest.json is rebuilt from what is on disk at the end of every run.
"""

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
GENERATE = os.path.join(HERE, "generate.py")
MANIFEST_VERSION = 2
TEST_FRACTION = 0.05
VAL_FRACTION = 0.03


def split_of(seed):
    """Deterministic split by scene: ~5% test, ~3% val, the rest train."""
    u = int(hashlib.sha256(("split:%d" % seed).encode()).hexdigest()[:8], 16) / 2.0 ** 32
    if u < TEST_FRACTION:
        return "test"
    if u < TEST_FRACTION + VAL_FRACTION:
        return "val"
    return "train"


def scene_dir(out, seed):
    return os.path.join(out, split_of(seed), "scene_%06d" % seed)


def parse_shard(text):
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError("--shard wants i/n, e.g. 0/4")
    if n < 1 or not 0 <= i < n:
        raise argparse.ArgumentTypeError("--shard i/n needs 0 <= i < n")
    return i, n


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output folder (shared by all shards)")
    p.add_argument("--scenes", type=int, default=10, help="number of scenes (seeds)")
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--seeds", default="", help="comma list of seeds; replaces --scenes/--first-seed")
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--spp", type=int, default=4, help="samples per pixel of each noisy stack")
    p.add_argument("--stacks", type=int, default=16, help="independent noisy renders per frame")
    p.add_argument("--gt-spp", type=int, default=1024)
    p.add_argument("--gt-depth", choices=["16", "32"], default="16", help="EXR bits of the GT renders")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--gt-count", type=int, choices=[0, 1, 2], default=2,
                   help="ground-truth renders per frame (2 for a data set, 1 for a reference)")
    p.add_argument("--seed-tag", default="",
                   help="mixed into every Cycles render seed: renders independent of a data set made "
                        "without it (same scenes and exposure), e.g. for a high-spp reference")
    p.add_argument("--shard", type=parse_shard, default=(0, 1), help="i/n: render every n-th scene from the i-th")
    p.add_argument("--threads", type=int, default=2, help="Cycles threads per Blender process")
    p.add_argument("--blender", default="blender",
                   help="Blender executable, or a Python with the bpy module (e.g. /work/venv-bpy/bin/python)")
    p.add_argument("--batch", type=int, default=20, help="scenes per Blender process (start-up is paid once)")
    p.add_argument("--profile", action="store_true", help="also time one extra EXR write per frame")
    p.add_argument("--manifest-only", action="store_true", help="only rebuild manifest.json from disk")
    p.add_argument("--export", help="also write the small manifest (settings, counts, per-frame checks) here")
    p.add_argument("--describe-only", metavar="FILE",
                   help="render nothing: build every scene of the range and write the frames each archetype "
                        "and lighting will get (the manifest's frame_counts) to FILE")
    args = p.parse_args(argv)
    try:
        args.seed_list = [int(x) for x in args.seeds.split(",") if x.strip()] if args.seeds else \
            list(range(args.first_seed, args.first_seed + args.scenes))
    except ValueError:
        p.error("--seeds wants a comma list of integers, got %r" % args.seeds)
    args.scenes = len(args.seed_list)
    if min(args.scenes, args.res, args.spp, args.stacks, args.gt_spp, args.frames, args.threads, args.batch) < 1:
        p.error("--scenes, --res, --spp, --stacks, --gt-spp, --frames, --threads and --batch must be positive")
    return args


def render_settings(args):
    return {"res": args.res, "spp": args.spp, "stacks": args.stacks, "gt_spp": args.gt_spp,
            "gt_depth": args.gt_depth, "frames": args.frames, "gt_count": args.gt_count,
            "seed_tag": args.seed_tag}


def read_json(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def frame_done(sdir, k, settings):
    """A frame counts only when meta.json (written last) and every file it lists exist."""
    meta = read_json(os.path.join(sdir, "frame_%d" % k, "meta.json"))
    if meta is None:
        return False
    defaults = {"gt_count": 2, "seed_tag": ""}  # frames made before these options existed
    mismatch = [key for key in ("res", "spp", "stacks", "gt_spp", "gt_depth", "gt_count", "seed_tag")
                if meta.get(key, defaults.get(key)) != settings[key]]
    if mismatch:
        sys.exit("make_dataset.py: %s/frame_%d was made with other settings (%s); use another --out"
                 % (sdir, k, ", ".join("%s=%s" % (m, meta.get(m, defaults.get(m))) for m in mismatch)))
    return all(os.path.exists(os.path.join(sdir, "frame_%d" % k, f)) for f in meta["files"])


def is_python(blender):
    """A Python interpreter with the bpy module rather than a Blender executable."""
    return "python" in os.path.basename(blender)


def blender_version(blender):
    cmd = [blender, "-c", "import bpy; print('Blender', bpy.app.version_string)"] if is_python(blender) \
        else [blender, "--version"]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=120).stdout
        lines = [line for line in out.splitlines() if line.startswith("Blender")]
        return lines[0].strip() if lines else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def describe(args, path):
    """Builds (does not render) every scene of the range in one Blender process; writes frame counts."""
    os.makedirs(os.path.join(args.out, "logs"), exist_ok=True)
    jobs_path = os.path.join(args.out, "logs", "describe_jobs.json")
    write_json_atomic(jobs_path, [{"seed": s, "scene_dir": scene_dir(args.out, s), "frames": []}
                                  for s in args.seed_list])
    out_path = os.path.join(args.out, "logs", "describe.json")
    log_path = os.path.join(args.out, "logs", "describe.log")
    with open(log_path, "w") as log:
        rc = subprocess.call(generator_command(args, jobs_path) + ["--describe", out_path], stdout=log,
                             stderr=subprocess.STDOUT)
    if rc != 0:
        sys.exit("make_dataset.py: Blender failed describing the scenes (exit %d); see %s" % (rc, log_path))
    scenes = [{"seed": d["seed"], "frames": [{"archetype": d["archetype"], "lighting": d["lighting"]}] * args.frames}
              for d in json.load(open(out_path))]
    data = {"what": "frames per archetype and lighting that make_dataset.py will render (scenes built, "
                    "not rendered)", "settings": render_settings(args),
            "seeds": {"first": args.first_seed, "count": args.scenes} if not args.seeds else args.seed_list,
            "scene_count": len(scenes), "frame_count": len(scenes) * args.frames,
            "frame_counts": count_frames(scenes)}
    write_json_atomic(path, data)
    os.remove(jobs_path)
    return data


def generator_command(args, jobs_path):
    settings = ["--jobs", jobs_path, "--res", str(args.res), "--spp", str(args.spp),
                "--stacks", str(args.stacks), "--gt-spp", str(args.gt_spp), "--gt-depth", args.gt_depth,
                "--frames", str(args.frames), "--threads", str(args.threads), "--gt-count", str(args.gt_count),
                "--seed-tag", args.seed_tag] + (["--profile"] if args.profile else [])
    if is_python(args.blender):
        return [args.blender, GENERATE] + settings
    return [args.blender, "-b", "--factory-startup", "--python", GENERATE, "--"] + settings


def render_batch(args, batch, log_dir, on_frame):
    """Renders [(seed, frames)] in one Blender process; on_frame(seed, k) after each finished frame."""
    first = batch[0][0]
    jobs_path = os.path.join(log_dir, "jobs_%06d.json" % first)
    write_json_atomic(jobs_path, [{"seed": seed, "scene_dir": scene_dir(args.out, seed), "frames": todo}
                                  for seed, todo in batch])
    log_path = os.path.join(log_dir, "batch_%06d.log" % first)
    started = time.time()
    with open(log_path, "w") as log:
        proc = subprocess.Popen(generator_command(args, jobs_path), stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, errors="replace")
        for line in proc.stdout:
            log.write(line)
            words = line.split()
            if words[:2] == ["SCENEGEN", "ready"]:
                cpu = float(words[3]) if len(words) > 3 else float("nan")
                log.write("make_dataset.py: start-up %.2f s, %.2f s CPU\n" % (float(words[2]) - started, cpu))
            elif words[:2] == ["SCENEGEN", "frame"] and len(words) >= 5:
                log.flush()
                on_frame(int(words[2]), int(words[3]))
        rc = proc.wait()
    if rc != 0:
        sys.exit("make_dataset.py: Blender failed on the batch from seed %d (exit %d); see %s"
                 % (first, rc, log_path))
    os.remove(jobs_path)


def write_json_atomic(path, data, indent=1):
    tmp = "%s.tmp%d" % (path, os.getpid())
    with open(tmp, "w") as f:
        json.dump(data, f, indent=indent)
    os.replace(tmp, path)


def format_seconds(s):
    s = int(s)
    return "%dh%02dm%02ds" % (s // 3600, s % 3600 // 60, s % 60) if s >= 3600 else "%dm%02ds" % (s // 60, s % 60)


def frame_entry(args, sdir, k, meta, checks):
    renders = meta["render_seconds"]
    stacks = [v for n, v in renders.items() if n.startswith("spp") and v is not None]
    gts = [v for n, v in renders.items() if n.startswith("gt") and v is not None]
    return {"frame": k, "path": os.path.relpath(os.path.join(sdir, "frame_%d" % k), args.out),
            "archetype": meta.get("archetype", "?"), "lighting": meta.get("lighting", "?"),
            "files": meta["files"], "render_seeds": meta["render_seeds"], "render_seconds": renders,
            "stack_seconds_total": round(sum(stacks), 3), "gt_seconds_total": round(sum(gts), 3),
            "frame_seconds": meta["frame_seconds"], "exposure_scale": meta["exposure_scale"],
            "blender_version": meta["blender_version"], "generator_version": meta["generator_version"],
            "checks": checks}


def count_frames(scenes):
    """Frames per archetype, per lighting, and per (archetype, lighting)."""
    by_arch, by_light, table = {}, {}, {}
    for scene in scenes:
        for f in scene["frames"]:
            a, l = f["archetype"], f["lighting"]
            by_arch[a] = by_arch.get(a, 0) + 1
            by_light[l] = by_light.get(l, 0) + 1
            table.setdefault(a, {})[l] = table.get(a, {}).get(l, 0) + 1
    return {"archetype": dict(sorted(by_arch.items())), "lighting": dict(sorted(by_light.items())),
            "archetype_lighting": {a: dict(sorted(v.items())) for a, v in sorted(table.items())}}


def write_manifest(args, bversion):
    """Scan every seed of the range (all shards) and describe the frames that are finished."""
    from dataset_checks import cached
    settings = render_settings(args)
    scenes = []
    counts = {"train": 0, "val": 0, "test": 0}
    for seed in args.seed_list:
        sdir = scene_dir(args.out, seed)
        frames = []
        for k in range(args.frames):
            if not frame_done(sdir, k, settings):
                continue
            meta = read_json(os.path.join(sdir, "frame_%d" % k, "meta.json"))
            frames.append(frame_entry(args, sdir, k, meta, cached(os.path.join(sdir, "frame_%d" % k),
                                                                  meta["files"])))
        if frames:
            counts[split_of(seed)] += 1
            scenes.append({"seed": seed, "split": split_of(seed),
                           "path": os.path.relpath(sdir, args.out), "frames": frames,
                           "complete": len(frames) == args.frames})
    versions = sorted({f["generator_version"] for s in scenes for f in s["frames"]})
    manifest = {
        "manifest_version": MANIFEST_VERSION, "generator_versions": versions,
        "blender_version": bversion, "settings": settings,
        "seeds": args.seed_list if args.seeds else {"first": args.first_seed, "count": args.scenes},
        "split_rule": {"test": TEST_FRACTION, "val": VAL_FRACTION,
                       "how": "u = first 32 bits of sha256('split:<seed>') / 2^32; test if u<0.05, val if u<0.08"},
        "scene_counts": counts, "frame_count": sum(len(s["frames"]) for s in scenes),
        "frame_counts": count_frames(scenes),
        "scenes": scenes,
    }
    write_json_atomic(os.path.join(args.out, "manifest.json"), manifest)
    return manifest


def export_checks(manifest, path):
    """The small manifest committed to git: settings, seeds, counts and per-frame checks."""
    frames = [[s["seed"], f["frame"], s["split"], f["archetype"], f["lighting"], f["checks"]]
              for s in manifest["scenes"] for f in s["frames"]]
    data = {key: manifest[key] for key in ("generator_versions", "blender_version", "settings", "seeds",
                                           "scene_counts", "frame_count", "frame_counts")}
    data["frame_fields"] = ["seed", "frame", "split", "archetype", "lighting", "checks"]
    data["frames"] = frames
    tmp = "%s.tmp%d" % (path, os.getpid())
    with open(tmp, "w") as f:  # one frame a line: small diffs, readable
        f.write(json.dumps({k: v for k, v in data.items() if k != "frames"}, indent=1)[:-2])
        f.write(',\n "frames": [\n')
        f.write(",\n".join("  " + json.dumps(fr, separators=(",", ":")) for fr in frames))
        f.write("\n ]\n}\n")
    os.replace(tmp, path)


def plan_work(args):
    """[(seed, frames still to render)] of this shard, in seed order."""
    settings = render_settings(args)
    shard_i, shard_n = args.shard
    seeds = [s for j, s in enumerate(args.seed_list) if j % shard_n == shard_i]
    work = [(s, [k for k in range(args.frames) if not frame_done(scene_dir(args.out, s), k, settings)])
            for s in seeds]
    return seeds, [(s, todo) for s, todo in work if todo]


def batches(work, size):
    return [work[i:i + size] for i in range(0, len(work), size)]


class Progress:
    """One line per finished frame on stderr: counts, rate, elapsed time and ETA."""

    def __init__(self, total, scenes):
        self.total, self.scenes, self.done, self.start = total, scenes, 0, time.time()
        self.seen = set()

    def frame(self, seed, k):
        self.done += 1
        self.seen.add(seed)
        elapsed = time.time() - self.start
        rate = self.done / elapsed
        eta = (self.total - self.done) / rate if rate > 0 else 0
        print("[%d/%d scenes, %d/%d frames] seed %d frame %d (%s): %.1f s/frame, %.0f frames/h, elapsed %s, ETA %s"
              % (len(self.seen), self.scenes, self.done, self.total, seed, k, split_of(seed), elapsed / self.done,
                 3600 * rate, format_seconds(elapsed), format_seconds(eta)), file=sys.stderr, flush=True)


def main(argv):
    args = parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    bversion = blender_version(args.blender)
    if args.manifest_only:
        m = write_manifest(args, bversion)
        print("manifest: %d frames in %d scenes" % (m["frame_count"], len(m["scenes"])), file=sys.stderr)
        if args.export:
            export_checks(m, args.export)
        return 0
    if bversion == "unknown":
        sys.exit("make_dataset.py: cannot run '%s' (Blender, or a Python with bpy)" % args.blender)
    if args.describe_only:
        d = describe(args, args.describe_only)
        print("make_dataset.py: %d scenes, %d frames described in %s" % (d["scene_count"], d["frame_count"],
                                                                        args.describe_only), file=sys.stderr)
        return 0
    log_dir = os.path.join(args.out, "logs")
    os.makedirs(log_dir, exist_ok=True)
    seeds, work = plan_work(args)
    total = sum(len(todo) for _, todo in work)
    print("make_dataset.py: shard %d/%d: %d scenes, %d frames to render, %d already done (%s)"
          % (args.shard[0], args.shard[1], len(seeds), total, len(seeds) * args.frames - total, bversion),
          file=sys.stderr, flush=True)
    progress = Progress(total, len(work))
    for batch in batches(work, args.batch):
        render_batch(args, batch, log_dir, progress.frame)
    m = write_manifest(args, bversion)
    if args.export:
        export_checks(m, args.export)
    print("make_dataset.py: manifest lists %d finished frames in %d scenes (%s)"
          % (m["frame_count"], len(m["scenes"]), ", ".join("%s %d" % kv for kv in m["scene_counts"].items())),
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
