#!/usr/bin/env python3
"""Plans the experiment: which frames, which methods, which rules.

Called by the Makefile at parse time with its variables as KEY=VALUE arguments.
Writes (only when the content changes, so Make's timestamps stay meaningful):
  OUT/plan.mk      explicit rules for every (method, split, scene, spp), included by
                   the Makefile, whose canned recipes (run_*, metrics) do the work
  OUT/plan.json    the same plan for choose.py and report.py
  OUT/args/*.args  the command-line arguments of every method at every spp
  OUT/stamp/*      the source folders, so pointing TEST_DIR elsewhere redoes the inputs
Prints the path of plan.mk. Exits non-zero with one line on stderr when the test
split has no frames.
"""

import glob
import json
import os
import sys

SPPS_PAPER = (4, 16, 64)


def write_if_changed(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    try:
        with open(path) as f:
            if f.read() == text:
                return
    except OSError:
        pass
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def evenly_spaced(items, count):
    """`count` items spread over the list (all of them when count is 0 or too large)."""
    if count <= 0 or count >= len(items):
        return list(items)
    return [items[(i * len(items)) // count] for i in range(count)]


def scan_split(split_dir, max_scenes, spps):
    """{scene name: {src, frames, spps, stack_spp, files}} of a data set split."""
    scenes = {}
    for scene_dir in sorted(glob.glob(os.path.join(split_dir, "scene_*"))):
        frames, usable, stack_spp = [], set(spps), None
        for meta_path in sorted(glob.glob(os.path.join(scene_dir, "frame_*", "meta.json"))):
            with open(meta_path) as f:
                meta = json.load(f)
            stack_spp = int(meta["spp"])
            usable &= {n for n in spps if n % stack_spp == 0 and n // stack_spp <= int(meta["stacks"])}
            frames.append(os.path.basename(os.path.dirname(meta_path)))
        if frames and usable:
            scenes[os.path.basename(scene_dir)] = {
                "src": os.path.abspath(scene_dir), "frames": frames,
                "spps": sorted(usable), "stack_spp": stack_spp}
    chosen = evenly_spaced(sorted(scenes), max_scenes)
    return {name: scenes[name] for name in chosen}


def source_files(scene):
    """Files an input/reference rule reads: the first stacks, the ground truths, meta.json."""
    stacks = max(scene["spps"]) // scene["stack_spp"]
    files = []
    for frame in scene["frames"]:
        d = os.path.join(scene["src"], frame)
        files += [os.path.join(d, f"spp{scene['stack_spp']}_{i:02d}.exr") for i in range(stacks)]
        files += [os.path.join(d, n) for n in ("meta.json", "gt_a.exr", "gt_b.exr", "gt_clean.exr")
                  if n != "gt_clean.exr" or os.path.exists(os.path.join(d, n))]
    return files


def model_for(var, family, spp):
    """The model file of a family at one spp: FAMILY_MODEL_<spp> if given, else FAMILY_MODEL."""
    return var.get(f"{family}_MODEL_{spp}") or var.get(f"{family}_MODEL", "")


def sweep_settings(text):
    """'27:0 27:18' -> [(27, 0), (27, 18)]"""
    settings = []
    for token in text.split():
        steps, skip = token.split(":")
        settings.append((int(steps), int(skip)))
    return settings


def method_table(var):
    """Every method of the tables, in row order, with how it runs."""
    samples = int(var.get("SAMPLES", "4"))
    seed = var.get("SEED", "0")
    dn = ["--seed", seed]
    return [
        {"name": "noisy", "label": "Noisy input", "runner": "none"},
        {"name": "oidn", "label": "OIDN 2.x (default quality)", "runner": "oidn",
         "args": ["--quality", "default"]},
        {"name": "oidn_high", "label": "OIDN 2.x (high quality)", "runner": "oidn",
         "args": ["--quality", "high"]},
        {"name": "isik", "label": "Isik et al. style kernel network", "runner": "dncleanse",
         "family": "ISIK", "args": []},
        {"name": "regression", "label": "Single-pass regression network", "runner": "dndenoise",
         "family": "REGRESSION", "args": dn},
        {"name": "base", "label": "Base prior alone (no Control Module), best steps/skip",
         "runner": "dndenoise", "family": "BASE", "args": dn,
         "sweep": sweep_settings(var.get("BASE_SWEEP", ""))},
        {"name": "ours", "label": "Ours (dndenoise defaults)", "runner": "dndenoise",
         "family": "OURS", "args": dn},
        {"name": "ours_nomatch", "label": "Ours without local mean matching (`--mean-match 0`)",
         "runner": "dndenoise", "family": "OURS", "args": dn + ["--mean-match", "0"]},
        {"name": "ours_fixed", "label": "Ours with the 4-spp defaults at every spp, no autoexposure "
         "(`--skip 18 --mean-match 2 --exposure 1`)", "runner": "dndenoise", "family": "OURS",
         "args": dn + ["--skip", "18", "--mean-match", "2", "--exposure", "1"]},
        {"name": "ours_best", "label": "Ours (best steps/skip)", "runner": "dndenoise",
         "family": "OURS", "args": dn, "sweep": sweep_settings(var.get("OURS_SWEEP", ""))},
        {"name": "ours_samples", "label": f"Ours (mean of {samples} samples)", "runner": "dndenoise",
         "family": "OURS", "args": dn + ["--samples", str(samples)]},
    ]


def resolve(var, methods, spps, pyoidn_ok):
    """Fills in per-spp models, arguments and the reason a method is skipped."""
    for m in methods:
        m["spps"], m["skipped"], m["models"], m["spp_args"] = [], {}, {}, {}
        for spp in spps:
            if m["runner"] == "oidn" and not pyoidn_ok:
                m["skipped"][spp] = "the pyoidn Python module is not importable"
                continue
            args = list(m.get("args", []))
            if "family" in m:
                model = model_for(var, m["family"], spp)
                if not model or not os.path.isfile(model):
                    m["skipped"][spp] = f"model file `{model or '(none)'}` does not exist"
                    continue
                m["models"][spp] = os.path.abspath(model)
                args = ["--model", os.path.abspath(model)] + args
            m["spp_args"][spp] = args
            m["spps"].append(spp)


def sweep_methods(methods):
    """One pseudo-method per (tuned method, setting), run on the tuning split."""
    sweeps = []
    for m in methods:
        m["candidates"] = []
        for steps, skip in m.get("sweep", []):
            name = f"{m['name']}@steps{steps}_skip{skip}"
            m["candidates"].append(name)
            sweeps.append({"name": name, "label": f"{m['label']}: --steps {steps} --skip {skip}",
                           "runner": m["runner"], "parent": m["name"], "steps": steps, "skip": skip,
                           "spps": list(m["spps"]), "models": m["models"],
                           "spp_args": {n: a + ["--steps", str(steps), "--skip", str(skip)]
                                        for n, a in m["spp_args"].items()}})
        if "sweep" in m and not m["sweep"]:
            for spp in m["spps"]:
                m["skipped"][spp] = "no settings to sweep (empty sweep variable)"
            m["spps"] = []
    return sweeps


class Rules:
    """Writes plan.mk: explicit rules calling the Makefile's canned recipes."""

    def __init__(self):
        self.variables, self.lines = [], []

    def rule(self, targets, prereqs, recipe, order_only=()):
        grouped = "&:" if len(targets) > 1 else ":"
        line = f"{' '.join(targets)} {grouped} {' '.join(prereqs)}"
        if order_only:
            line += " | " + " ".join(order_only)
        self.lines += [line, "\t" + recipe, ""]

    def var(self, name, values):
        """Variables go first: Make expands a rule's prerequisites when it reads the rule."""
        self.variables.append(f"{name} := {' '.join(values)}")

    def text(self):
        return "\n".join(["# Generated by configure.py; do not edit.", ""] + self.variables + [""] + self.lines) + "\n"


def case_paths(out, kind, method, split, scene, frames, spp, ext="exr"):
    base = os.path.join(out, kind, method, split, scene) if method else os.path.join(out, kind, split, scene)
    return [os.path.join(base, f"{f}_spp{spp}.{ext}") for f in frames]


def plan(var):
    out = os.path.abspath(var["OUT"])
    spps = [int(s) for s in var.get("SPPS", "4 16 64").split()]
    splits = {"test": var["TEST_DIR"], "tune": var["TUNE_DIR"]}
    scenes = {"test": scan_split(splits["test"], int(var.get("TEST_SCENES", "0")), spps),
              "tune": scan_split(splits["tune"], int(var.get("TUNE_SCENES", "0")), spps)}
    if not scenes["test"]:
        print(f"configure: {splits['test']}: no frames with meta.json and enough stacks for "
              f"spp {spps}", file=sys.stderr)
        sys.exit(1)
    methods = method_table(var)
    resolve(var, methods, spps, var.get("PYOIDN_OK") == "1")
    tune_spps = {n for scene in scenes["tune"].values() for n in scene["spps"]}
    for m in methods:
        if m.get("sweep"):
            for spp in [n for n in m["spps"] if n not in tune_spps]:
                m["skipped"][spp] = "the tuning split has no frames at this spp"
            m["spps"] = [n for n in m["spps"] if n in tune_spps]
            m["spp_args"] = {n: a for n, a in m["spp_args"].items() if n in tune_spps}
    sweeps = sweep_methods(methods)
    tuned = {m["name"] for m in methods if m.get("candidates")}

    rules = Rules()
    tools = {"dndenoise": "$(DNDENOISE)", "dncleanse": "$(DNCLEANSE)", "oidn": "$(OIDN_SCRIPT)"}
    all_metrics = {"test": [], "tune": []}

    for split, split_scenes in scenes.items():
        stamp = os.path.join(out, "stamp", f"source_{split}.txt")
        write_if_changed(stamp, os.path.abspath(splits[split]) + "\n")
        for scene_name, scene in split_scenes.items():
            targets = [os.path.join(out, "ref", split, scene_name, f"{f}.exr") for f in scene["frames"]]
            for spp in scene["spps"]:
                targets += case_paths(out, "input", None, split, scene_name, scene["frames"], spp)
            rules.rule(targets, source_files(scene) + [stamp, "$(INPUT_SCRIPTS)"],
                       f"$(call make_inputs,{scene['src']},{' '.join(scene['frames'])},"
                       f"{' '.join(map(str, scene['spps']))},{os.path.join(out, 'input', split, scene_name)},"
                       f"{os.path.join(out, 'ref', split, scene_name)})")

    def args_file(name, spp):
        return os.path.join(out, "args", f"{name}_spp{spp}.args")

    for m in methods + sweeps:
        for spp, args in m["spp_args"].items():
            if m["name"] not in tuned:
                write_if_changed(args_file(m["name"], spp), " ".join(args) + "\n")

    runs = [(m, "test") for m in methods] + [(s, "tune") for s in sweeps]
    for m, split in runs:
        name = m["name"]
        for scene_name, scene in scenes[split].items():
            for spp in [n for n in scene["spps"] if n in m["spps"]]:
                inputs = case_paths(out, "input", None, split, scene_name, scene["frames"], spp)
                refs = [os.path.join(out, "ref", split, scene_name, f"{f}.exr") for f in scene["frames"]]
                if m["runner"] == "none":
                    results = inputs
                else:
                    results = case_paths(out, "res", name, split, scene_name, scene["frames"], spp)
                    deps = inputs + [args_file(name, spp), tools[m["runner"]]]
                    deps += [m["models"][spp]] if spp in m.get("models", {}) else []
                    rules.rule(results, deps, f"$(call run_{m['runner']},{args_file(name, spp)},"
                               f"{' '.join(inputs)},{os.path.dirname(results[0])}/)")
                jsons = case_paths(out, "metrics", name, split, scene_name, scene["frames"], spp, "json")
                heat = "1" if split == "test" else ""
                targets = jsons + ([j[:-4] + "png" for j in jsons] if heat else [])
                rules.rule(targets, results + refs + ["$(DNMETRICS)"],
                           f"$(call metrics,{' '.join(refs)},{' '.join(results)},{' '.join(jsons)},{heat})")
                all_metrics[split] += jsons

    # The choice of a tuned method at one spp depends on its candidates' metrics.
    for m in methods:
        if m["name"] not in tuned:
            continue
        for spp in m["spps"]:
            jsons = [j for j in all_metrics["tune"] if f"/metrics/{m['name']}@" in j and j.endswith(f"_spp{spp}.json")]
            choice = os.path.join(out, "choice", f"{m['name']}_spp{spp}.json")
            rules.rule([args_file(m["name"], spp), choice], jsons + ["$(OUT)/plan.json", "$(CHOOSE_SCRIPT)"],
                       f"$(call choose,{m['name']},{spp})")

    fvvdp = []
    if var.get("FVVDP_OK") == "1":
        for m in methods:
            for spp in m["spps"]:
                cases = [(name, scene, frame) for name, scene in scenes["test"].items()
                         if spp in scene["spps"] for frame in scene["frames"]]
                cases = evenly_spaced(cases, int(var.get("FVVDP_FRAMES", "0")))
                if not cases:
                    continue
                pairs, deps = [], []
                for name, scene, frame in cases:
                    kind, method = ("input", None) if m["runner"] == "none" else ("res", m["name"])
                    result = case_paths(out, kind, method, "test", name, [frame], spp)[0]
                    ref = os.path.join(out, "ref", "test", name, f"{frame}.exr")
                    pairs += [ref, result]
                    deps += [ref, result]
                target = os.path.join(out, "fvvdp", f"{m['name']}_spp{spp}.json")
                rules.rule([target], deps + ["$(FVVDP_SCRIPT)"], f"$(call fvvdp,{target},{' '.join(pairs)})")
                fvvdp.append(target)

    speed = []
    for m in methods:
        if m["runner"] == "none" or not m["spps"]:
            continue
        spp = m["spps"][0]
        target = os.path.join(out, "speed", f"{m['name']}.json")
        deps = ["$(SPEED_INPUTS)", args_file(m["name"], spp), tools[m["runner"]], "$(SPEED_SCRIPT)"]
        deps += [m["models"][spp]] if spp in m.get("models", {}) else []
        rules.rule([target], deps, f"$(call speed,{m['runner']},{args_file(m['name'], spp)},{target})",
                   order_only=["$(TEST_METRICS)", "$(FVVDP_RESULTS)"])
        speed.append(target)

    first_scene = next(iter(scenes["test"].values()))
    first_name = next(iter(scenes["test"]))
    speed_source = case_paths(out, "input", None, "test", first_name, first_scene["frames"][:1],
                              min(first_scene["spps"]))[0]
    rules.var("SPEED_SOURCE", [speed_source])
    rules.var("TEST_METRICS", all_metrics["test"])
    rules.var("TUNE_METRICS", all_metrics["tune"])
    rules.var("SPEED_RESULTS", speed)
    rules.var("FVVDP_RESULTS", fvvdp)
    rules.var("CHOICES", [args_file(m["name"], n) for m in methods if m["name"] in tuned for n in m["spps"]])

    plan_json = {
        "out": out, "spps": spps, "splits": {k: os.path.abspath(v) for k, v in splits.items()},
        "scenes": scenes, "methods": methods, "sweeps": sweeps,
        "settings": {k: var.get(k, "") for k in ("TEST_SCENES", "TUNE_SCENES", "SAMPLES", "SEED",
                                                  "BASE_SWEEP", "OURS_SWEEP", "TUNE_METRIC", "THREADS",
                                                  "SPEED_SIZE", "SPEED_SMALL", "SPEED_REPEATS", "BIN",
                                                  "FVVDP_OK", "FVVDP_FRAMES", "FVVDP_DISPLAY",
                                                  "FVVDP_PYTHON")},
        "note": var.get("NOTE", ""),
    }
    write_if_changed(os.path.join(out, "plan.json"), json.dumps(plan_json, indent=1, default=str) + "\n")
    write_if_changed(os.path.join(out, "plan.mk"), rules.text())
    print(os.path.join(out, "plan.mk"))


def main():
    var = dict(a.split("=", 1) for a in sys.argv[1:])
    plan(var)


if __name__ == "__main__":
    main()
