#!/usr/bin/env python3
"""Regenerates docs/RESULTS.md, the whole page, in one command:

  make -C experiments results            (= python3 experiments/results.py)

1. Renders the evaluation sets that are missing (resumable; --no-render scores only what
   exists): Blender 5, Mitsuba with a box and with a Gaussian pixel filter
   (render_evaldata.sh, into --evaldata) and the user-style Blender 3.4 scenes
   (user_scenes.py, into --user), and the test split of the Cycles 3.4 data set: its 16
   test seeds among seeds 0-299, frame 0, 16 stacks of 4 spp and a 2 x 256-spp reference
   (scenegen/make_dataset.py, into --test-split's parent).
2. Scores every method on every set with eval_sets.py (results in WORK/<name>, kept
   between runs with --reuse).
3. Times the default's quality levels against OIDN's two modes (bench/speed_vs_oidn.py);
   with --no-speed the page keeps the table the last timed run stored in WORK.
4. Writes the page: the default against OIDN's usual call and OIDN's prefilter mode first,
   then the quality levels and speed, then the ablations, each with its model file.
   Sections other scripts keep in the page (<!-- NAME: begin --> ... <!-- NAME: end -->)
   are carried over at its end.
5. Inserts the hand-kept notes of experiments/results_notes/: which sets chose each setting
   and which were held out (sets.md, after the list of sets), the temporal measurements
   (temporal.md) and the measurements behind the defaults (measurements.md), at the end.
   `--notes-only` refreshes just these sections in the existing page (no scoring, no
   rendering: for a machine without the scored results in WORK).
"""

import argparse
import datetime
import os
import platform
import re
import shlex
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import eval_sets  # noqa: E402

USER_SCENES = ("cube", "interior", "studio", "night", "kitchen", "outdoor", "product")

# name, what it is, model file (None: not a model of ours), eval_sets.py arguments
OIDN = [
    ("oidn", "OIDN 2.5.1, its usual call (colour + albedo + normal)", None, ["--oidn"]),
    ("oidn_pre", "OIDN 2.5.1, its prefilter mode (Blender's \"Accurate\")", None,
     ["--oidn", "--", "--prefilter"]),
]
DEFAULT = ("default", "dndenoise, the default (`-q balanced`)", "models/default.dnm", [])
LEVELS = [
    ("fast", "dndenoise -q fast", "models/default.dnm", ["--", "-q", "fast"]),
    ("high", "dndenoise -q high", "models/default.dnm", ["--", "-q", "high"]),
]
ABLATIONS = [
    ("noisy", "the noisy input", None, []),
    ("base", "the pretrained base alone: OIDN's networks in this project's code", "models/oidn.dnm",
     ["--", "--model", "models/oidn.dnm"]),
    ("control_on", "the Control Module forced on (`--control on`)", "models/default.dnm",
     ["--", "--control", "on"]),
    ("scratch", "the from-scratch diffusion model (an experiment; it needs Cycles' light passes)",
     "models/diffusion-scratch.dnm", ["--skip-unusable", "--", "--model", "models/diffusion-scratch.dnm"]),
    ("isik", "the Isik-style kernel-predicting network (`dncleanse`; it needs Cycles' buffers)",
     "models/isik.pt",
     ["--skip-unusable", "--isik", "models/isik.pt"]),
]
NOTES = os.path.join(HERE, "results_notes")
NOTES_TOP = ("sets.md",)                         # after the list of sets
NOTES_END = ("temporal.md", "measurements.md")   # at the end of the page
# sections this page regenerates itself (temporal_eval.py: the temporal notes' old place)
KEPT_ELSEWHERE = ("eval_sets.py", "temporal_eval.py") + tuple(
    f"results_notes/{n}" for n in NOTES_TOP + NOTES_END)


def note_section(name):
    """A hand-kept note of experiments/results_notes/, between markers."""
    with open(os.path.join(NOTES, name)) as f:
        body = f.read().strip("\n")
    return f"<!-- results_notes/{name}: begin -->\n{body}\n<!-- results_notes/{name}: end -->"


def refresh_notes(path):
    """The existing page with its notes sections replaced by the templates' current text."""
    text = open(path).read()
    for name in KEPT_ELSEWHERE:
        if name == "eval_sets.py":
            continue
        begin, end = f"<!-- {name}: begin -->", f"<!-- {name}: end -->"
        while begin in text and end in text:
            head, rest = text.split(begin, 1)
            text = head.rstrip("\n") + "\n\n" + rest.split(end, 1)[1].lstrip("\n")
    anchor = "## The default against OIDN"
    head, rest = text.split(anchor, 1)
    top = "\n\n".join(note_section(n) for n in NOTES_TOP)
    text = f"{head.rstrip()}\n\n{top}\n\n{anchor}{rest}".rstrip("\n")
    return text + "\n\n" + "\n\n".join(note_section(n) for n in NOTES_END) + "\n"


def run(cmd, **kw):
    print("results:", shlex.join(cmd), flush=True)
    subprocess.run(cmd, check=True, cwd=ROOT, **kw)


def test_seeds(count=300):
    sys.path.insert(0, os.path.join(ROOT, "scenegen"))
    from make_dataset import split_of  # noqa: E402
    return [seed for seed in range(count) if split_of(seed) == "test"]


def render(args):
    run([sys.executable, os.path.join(ROOT, "scenegen", "make_dataset.py"),
         "--out", os.path.dirname(os.path.abspath(args.test_split)),
         "--seeds", ",".join(map(str, test_seeds())), "--frames", "1", "--res", "128", "--spp", "4",
         "--stacks", "16", "--gt-spp", "256", "--threads", str(args.threads)], stdout=subprocess.DEVNULL)
    env = dict(os.environ, THREADS=str(args.threads))
    run([os.path.join(HERE, "render_evaldata.sh"), args.evaldata], env=env)
    os.makedirs(args.user, exist_ok=True)
    for scene in USER_SCENES:
        run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python",
             os.path.join(HERE, "user_scenes.py"), "--", "--scene", scene, "--out", args.user,
             "--res", args.user_res, "--spp", "4", "16", "64", "--ref-spp", "1024",
             "--threads", str(args.threads)], stdout=subprocess.DEVNULL)


def score(args, methods):
    sets = ["--test-split", args.test_split, "--user", args.user, "--evaldata", args.evaldata,
            "--work", args.work, "--bin", args.bin, "--threads", str(args.threads)]
    for name, _, _, extra in methods:
        reuse = ["--reuse"] if args.reuse else []
        run([sys.executable, os.path.join(HERE, "eval_sets.py"), "--name", name, *sets, *reuse,
             *extra])


def speed_lines(args):
    """The speed benchmark's table: measured now, or with --no-speed the one the last
    run stored in WORK (which says when it was measured)."""
    stored = os.path.join(args.work, "speed.md")
    if args.no_speed:
        if os.path.exists(stored):
            return open(stored).read().rstrip().splitlines()
        return ["Not measured (`--no-speed`); [dndenoise.md](dndenoise.md#speed-and-memory) "
                "has the latest figures and their commands."]
    cmd = [sys.executable, os.path.join(ROOT, "bench", "speed_vs_oidn.py"), "--bin", args.bin]
    print("results:", shlex.join(cmd), flush=True)
    out = subprocess.run(cmd, check=True, cwd=ROOT, capture_output=True, text=True).stdout
    lines = [f"`python3 bench/speed_vs_oidn.py --bin {os.path.relpath(args.bin, ROOT)}` on "
             f"{datetime.date.today()} (whole process per frame at 1920x1080, medians of 3 "
             "interleaved rounds):", "", "```text", *out.rstrip().splitlines(), "```"]
    os.makedirs(args.work, exist_ok=True)
    with open(stored, "w") as f:
        f.write("\n".join(lines) + "\n")
    return lines


def method_list(methods):
    lines = ["| name | method | model file | eval_sets.py arguments |", "|---|---|---|---|"]
    for name, what, model, extra in methods:
        lines.append(f"| `{name}` | {what} | {f'`{model}`' if model else '-'} | "
                     f"`{' '.join(extra) or '(none)'}` |")
    return lines


def kept_sections(path):
    """Sections other scripts write into the page, verbatim."""
    if not os.path.exists(path):
        return []
    text, kept = open(path).read(), []
    while "<!-- " in text:
        head, _, text = text.partition("<!-- ")
        marker, _, text = text.partition(" -->")
        if not marker.endswith(": begin"):
            continue
        name = marker[: -len(": begin")]
        body, _, text = text.partition(f"<!-- {name}: end -->")
        if name not in KEPT_ELSEWHERE:
            kept.append(f"<!-- {name}: begin -->{body}<!-- {name}: end -->")
    return kept


def page(args, command):
    names = [m[0] for m in OIDN + [DEFAULT] + LEVELS + ABLATIONS]
    results, _ = eval_sets.load_results(args.work, names)
    frames = sorted({k for k in results["default"]})
    sets = sorted({k[0] for k in frames})
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    load = os.getloadavg()[0]
    lines = [
        "# Results", "",
        f"Generated by `{command}` on {datetime.date.today()} at commit `{commit}`; do not edit by "
        "hand: rerun the command. Machine: "
        f"{os.cpu_count()} cores ({platform.processor() or platform.machine()}), load average "
        f"{load:.1f} when the page was written.", "",
        f"Sets scored: {', '.join(f'`{s}`' for s in sets)} ({len({(k[0], k[1]) for k in frames})} renders, "
        "each at 4, 16 and 64 spp). `test`: the Cycles 3.4 test split; `user`: hand-built Blender 3.4 "
        "scenes rendered as a user renders them (experiments/user_scenes.py); `blender5`: Blender 5.0 "
        "(PyPI `bpy`); `mitsuba_box`, `mitsuba_gauss`: Mitsuba 3 with a box and with its default "
        "Gaussian pixel filter, which splats samples and correlates the noise "
        "(experiments/render_evaldata.sh). A set missing here was not rendered in this run. Means over "
        "frames of PSNR (dB, Reinhard tonemap), FLIP and L1 (HDR), as `dnmetrics` computes them; "
        "higher PSNR, lower FLIP and L1 are better.", "",
        *[note_section(n) + "\n" for n in NOTES_TOP],
        "## The default against OIDN", "",
        "`default`: `dndenoise` with no options, `models/default.dnm` (OIDN's networks in their prefilter "
        "mode, and the Control Module where the gate opens); `oidn`, `oidn_pre`: OIDN 2.5.1 itself through "
        "the `pyoidn` wheel, its usual call and its prefilter mode.", "",
    ]
    lines += eval_sets.table_lines({n: results[n] for n in ("oidn", "oidn_pre", "default")},
                                   ["oidn", "oidn_pre", "default"])
    lines += ["", "## Quality levels", "",
              "`-q fast` runs one network on the buffers as rendered, `-q balanced` (the default, "
              "`default` here) OIDN's prefilter mode, `-q high` adds the light-path split where Cycles "
              "wrote the diffuse passes ([dndenoise.md](dndenoise.md#speed-and-memory)).", ""]
    lines += eval_sets.table_lines({n: results[n] for n in ("oidn", "fast", "default", "high")},
                                   ["oidn", "fast", "default", "high"])
    lines += ["", "## Speed", ""] + speed_lines(args)
    lines += ["", "## Ablations", "",
              "Each against the default on the renders it could denoise; the model file is named in "
              "each heading.", ""]
    for name, what, model, _ in ABLATIONS:
        lines += [f"### `{name}`: {what}" + (f", `{model}`" if model else ""), ""]
        lines += eval_sets.table_lines({n: results[n] for n in (name, "default")}, [name, "default"])
        lines += [""]
    lines += ["", "## Methods", ""] + method_list(OIDN + [DEFAULT] + LEVELS + ABLATIONS)
    lines += ["", "Each row of the tables above was made by `python3 experiments/eval_sets.py --name "
              "NAME ARGUMENTS` with the sets' folders; OIDN runs through the `pyoidn` wheel "
              "(experiments/oidn_denoise.py)."]
    for section in kept_sections(args.results):
        lines += ["", section]
    for name in NOTES_END:
        lines += ["", note_section(name)]
    return "\n".join(lines) + "\n"


def machine_neutral(text):
    """The page without this machine's folders: the repository's own paths
    relative to it, a benchmark's temporary frame by its name."""
    text = re.sub(r"/tmp/tmp\w+/", "", text)
    return re.sub(re.escape(ROOT) + r"/(?:bench/\.\./)?", "", text)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--evaldata", default="/work/evaldata")
    p.add_argument("--user", default="/work/evaldata/user")
    p.add_argument("--user-res", default="384x216")
    p.add_argument("--test-split", default="/work/data/scenes/test")
    p.add_argument("--work", default="/work/eval")
    p.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--results", default=os.path.join(ROOT, "docs", "RESULTS.md"))
    p.add_argument("--no-render", action="store_true", help="score only the renders that exist")
    p.add_argument("--no-speed", action="store_true",
                   help="do not time: the page keeps the table the last timed run stored in WORK")
    p.add_argument("--reuse", action="store_true", help="keep results already scored in WORK")
    p.add_argument("--page-only", action="store_true", help="write the page from stored results")
    p.add_argument("--notes-only", action="store_true",
                   help="refresh only the sections from experiments/results_notes/ in the existing page")
    args = p.parse_args()
    command = "python3 experiments/results.py" + "".join(
        f" {a}" for a in sys.argv[1:])
    if args.notes_only:
        text = refresh_notes(args.results)
    else:
        if not args.page_only:
            if not args.no_render:
                render(args)
            score(args, OIDN + [DEFAULT] + LEVELS + ABLATIONS)
        text = page(args, command)
    tmp = f"{args.results}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(machine_neutral(text))
    os.replace(tmp, args.results)
    print(f"results: wrote {args.results}")


if __name__ == "__main__":
    main()
