#!/usr/bin/env python3
"""The four tools against the robustness table (tests/robustness_cases.py):
odd options, outputs over inputs, non-finite values, frame sequences and
provenance, on small files generated here and tiny models trained here.

Every case checks its exit code, a fragment of its message, that no signal
ended the tool, that its protected files kept their bytes and that no
temporary file was left behind; at the end no generated input may have changed.
"""
import argparse
import concurrent.futures
import csv
import hashlib
import io
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time

try:
    import numpy as np
    import OpenEXR
except ImportError as e:  # CTest reports this as skipped
    print(f"skipped: {e}")
    sys.exit(77)

sys.path.insert(0, os.path.dirname(__file__))
from cli_checks import check, run, summary  # noqa: E402
from exr_numpy import read_rgb, write_rgb  # noqa: E402
from robustness_cases import CASES  # noqa: E402


def sha(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def exr_channels(path):
    with OpenEXR.File(path, separate_channels=True) as f:
        return {k: v.pixels.copy() for k, v in f.channels().items()}


def exr_header(path):
    with OpenEXR.File(path) as f:
        return dict(f.header())


def write_exr(path, channels):
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as f:
        f.write(path)


def make_fixtures(w, bins):
    """Small inputs and tiny models; returns {placeholder: path}."""
    p = lambda *n: os.path.join(w, *n)  # noqa: E731
    here = os.path.dirname(os.path.abspath(__file__))
    data = p("data")
    subprocess.run([sys.executable, os.path.join(here, "make_tiny_dataset.py"), data, "--size", "32",
                    "--frames", "1", "--stacks", "1"], check=True)
    tiny = ["--batch", "1", "--crop", "16", "--threads", "1", "--spp", "4", "--val-every", "0"]
    for cmd in ([bins["dntrain"], "base", "--data", data, "--out", p("base.dnm"), "--steps", "1",
                 "--base-channels", "8", "--res-blocks", "1"] + tiny,
                [bins["dntrain"], "control", "--data", data, "--base", p("base.dnm"), "--steps", "1",
                 "--out", p("model.dnm")] + tiny,
                [bins["dncleanse"], "train", "--data", data, "--out", p("cleanser.pt"), "--steps", "1",
                 "--buffers", "albedo,normal", "--widths", "4,4", "--dilations", "1", "--feature-dims", "2",
                 "--batch", "1", "--crop", "16", "--threads", "1"]):
        out = run(cmd)
        if out.returncode != 0:
            sys.exit(f"fixture command failed: {shlex.join(cmd)}\n{out.stderr}")
    frame_dir = os.path.join(data, "val", "scene_0", "frame_0")
    files = {"w": w, "data": data, "base": p("base.dnm"), "model": p("model.dnm"), "cleanser": p("cleanser.pt")}
    files["frame"] = p("frame.exr")
    models = os.path.join(os.path.dirname(bins["dndenoise"]), "..", "models")
    files["shipped"] = os.path.realpath(os.path.join(models, "default.dnm"))
    files["oidn_base"] = os.path.realpath(os.path.join(models, "oidn.dnm"))
    shutil.copy(os.path.join(frame_dir, "spp4_00.exr"), files["frame"])
    files["ref"] = p("ref.exr")
    shutil.copy(os.path.join(frame_dir, "gt_a.exr"), files["ref"])
    files["small"] = p("small.exr")
    write_rgb(files["small"], np.full((16, 16, 3), 0.5, np.float32))
    rng = np.random.default_rng(3)
    files["rgb"], files["rgb2"] = p("rgb.exr"), p("rgb2.exr")
    write_rgb(files["rgb"], rng.random((32, 32, 3)).astype(np.float32))
    write_rgb(files["rgb2"], rng.random((32, 32, 3)).astype(np.float32))
    files["oddname"] = p('odd, "name".exr')
    files["oddname2"] = p('odd "quoted" \\ name.exr')
    for name in ("oddname", "oddname2"):
        shutil.copy(files["rgb2"], files[name])
    # A pixel at the top of float's range, in a frame the models can read.
    channels = exr_channels(files["frame"])
    for c in "RGB":
        channels[f"ViewLayer.Combined.{c}"][5, 5] = 3.4e38
    files["huge"] = p("huge.exr")
    write_exr(files["huge"], channels)
    # Links to inputs.
    files["link"], files["hardlink"], files["rgblink"] = p("link.exr"), p("hard.exr"), p("rgblink.exr")
    os.symlink(files["frame"], files["link"])
    os.link(files["frame"], files["hardlink"])
    os.symlink(files["rgb"], files["rgblink"])
    files["baselink"] = p("baselink.dnm")
    os.symlink(files["base"], files["baselink"])
    files["linkdir"] = p("linkdir")
    os.symlink(w, files["linkdir"])
    files["textmodel"] = p("text.dnm")
    with open(files["textmodel"], "w") as f:
        f.write("not a model\n")
    # Two folders holding the same file name, and an output folder.
    for d in ("dup_a", "dup_b"):
        files[d] = p(d)
        os.makedirs(files[d])
        files[d + "_x"] = os.path.join(files[d], "x.exr")
        shutil.copy(files["frame"], files[d + "_x"])
    files["outdir"] = p("outdir")
    os.makedirs(files["outdir"])
    # A sequence with frame 3 missing.
    files["seq"], files["seqout"] = p("seq"), p("seqout")
    os.makedirs(files["seq"])
    os.makedirs(files["seqout"])
    for n in (1, 2, 4):
        shutil.copy(files["frame"], os.path.join(files["seq"], f"shot.{n:04d}.exr"))
    files["seq1"] = os.path.join(files["seq"], "shot.0001.exr")
    return files


# ------------------------------------------------------------ result checks
# Each takes (files, completed process) and returns (ok, detail).

def _provenance(path, tool, files, model=None):
    h = exr_header(path)
    ok = str(h.get("Software", "")).startswith(tool) and tool in str(h.get("ImageHistory", ""))
    ok = ok and tool in str(h.get("dn:command", ""))
    if model:
        ok = ok and h.get("dn:model_sha256") == sha(model) and h.get("dn:model") == os.path.basename(model)
    return ok, {k: v for k, v in h.items() if k in ("Software", "ImageHistory", "dn:command", "dn:model",
                                                     "dn:model_sha256")}


def _outputs(files, names, absent=()):
    d = files["seqout"]
    return (all(os.path.exists(os.path.join(d, n)) for n in names)
            and not any(os.path.exists(os.path.join(d, n)) for n in absent)), sorted(os.listdir(d))


def _finite(path, layer, expect_max):
    rgb = read_rgb(path, layer)
    return np.isfinite(rgb).all() and (not expect_max or rgb.max() == np.finfo(np.float32).max), rgb.max()


def _csv_rows(out):
    return list(csv.reader(io.StringIO(out.stdout)))


# The version --version must print: the one CMakeLists.txt gives the project.
with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "CMakeLists.txt")) as _cmake:
    PROJECT_VERSION = re.search(r"project\(\S+ VERSION (\S+)", _cmake.read()).group(1)

CHECKS = {
    "version": lambda f, o: (PROJECT_VERSION in o.stdout and "OpenImageIO" in o.stdout, o.stdout),
    "version_no_torch": lambda f, o: ("LibTorch" not in o.stdout, o.stdout),
    "no_cuda": lambda f, o: (len(o.stderr.strip().splitlines()) == 1, o.stderr),
    "provenance_dndenoise": lambda f, o: _provenance(os.path.join(f["w"], "out.exr"), "dndenoise", f, f["model"]),
    "provenance_dncleanse": lambda f, o: _provenance(os.path.join(f["w"], "c.exr"), "dncleanse", f, f["cleanser"]),
    "provenance_heatmap": lambda f, o: _provenance(os.path.join(f["w"], "heat.exr"), "dnmetrics", f),
    "one_missing_line": lambda f, o: (len(re.findall(r"missing frame \d+$", o.stderr, re.M)) == 1
                                      and "--skip-missing" in o.stderr, o.stderr),
    "skip_missing_outputs": lambda f, o: _outputs(f, ["s.0001.exr", "s.0002.exr", "s.0004.exr"]),
    "frames_1_2": lambda f, o: _outputs(f, ["f.0001.exr", "f.0002.exr"], ["f.0004.exr"]),
    "printf_outputs": lambda f, o: _outputs(f, ["p.0001.exr", "p.0002.exr", "p.0004.exr"]),
    "at_output": lambda f, o: _outputs(f, ["at.0001.exr"]),
    "finite_dndenoise": lambda f, o: _finite(os.path.join(f["w"], "huge_out.exr"), "ViewLayer.Denoised", False),
    "finite_dncleanse": lambda f, o: _finite(os.path.join(f["w"], "huge_c.exr"), "ViewLayer.Cleansed", False),
    "json_inf": lambda f, o: (json.loads(o.stdout)["results"][0]["psnr"] == "inf", o.stdout),
    "csv_inf": lambda f, o: (_csv_rows(o)[1][1] == "inf", o.stdout),
    "csv_quoted": lambda f, o: (_csv_rows(o)[1][0] == f["oddname"], o.stdout),
    "json_escaped": lambda f, o: (json.loads(o.stdout)["results"][0]["file"] == f["oddname2"], o.stdout),
}


def temporaries(w, pid=None):
    """Temporary files (".NAME.tmpPID-N.ext") in w, of one process or of all."""
    mark = f".tmp{pid}-" if pid else ".tmp"
    found = []
    for root, _, names in os.walk(w):
        found += [os.path.join(root, n) for n in names if mark in n]
    return found


def run_case(case, files, subst, quoted):
    """Runs one row; returns what the checks need. Called from worker threads."""
    cmd = shlex.split(case.cmd.format(**quoted))
    env = dict(os.environ)
    env.pop("DN_MODEL", None)
    for k, v in (case.env or {}).items():
        env[k] = v.format(**subst)
    keep = {k: sha(files[k]) for k in case.keep}
    t0 = time.time()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        stdout, stderr = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:  # a hang is a failure of its row, not of the test
        proc.kill()
        stdout, stderr = proc.communicate()
        stderr += "\n(killed after 120 s)"
    out = subprocess.CompletedProcess(cmd, proc.returncode, stdout, stderr)
    changed = [k for k, h in keep.items() if sha(files[k]) != h]
    return cmd, out, time.time() - t0, changed, temporaries(files["w"], proc.pid)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--work-dir", required=True)
    ap.add_argument("-k", help="run only the cases whose name holds this text")
    args = ap.parse_args()
    w = os.path.abspath(args.work_dir)
    shutil.rmtree(w, ignore_errors=True)
    os.makedirs(w)
    bins = {t: os.path.join(os.path.abspath(args.bin), t) for t in ("dndenoise", "dnmetrics", "dncleanse", "dntrain")}
    start = time.time()
    files = make_fixtures(w, bins)
    print(f"fixtures in {time.time() - start:.1f} s", flush=True)
    inputs = {k: v for k, v in files.items() if os.path.isfile(v) and not os.path.islink(v)}
    before = {k: sha(v) for k, v in inputs.items()}
    subst = {**files, **bins}
    quoted = {k: shlex.quote(v) for k, v in subst.items()}
    cases = [c for c in CASES if not args.k or args.k in c.name]
    # Two at a time: most rows are a tool refusing an option, and starting
    # LibTorch dominates them. Outputs of different rows never share a name.
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        results = pool.map(lambda c: run_case(c, files, subst, quoted), cases)
        for case, (cmd, out, seconds, changed, tmp) in zip(cases, results):
            label = f"{case.name} ({seconds:.1f} s)"
            text = out.stdout if "--version" in cmd else out.stderr
            ok = out.returncode == case.code and case.message in text and 0 <= out.returncode < 128
            check(f"{label}: exit {case.code}, says '{case.message}'", ok,
                  f"exit {out.returncode}, stderr {out.stderr!r}, command {shlex.join(cmd)}")
            if case.keep:
                check(f"{label}: {', '.join(case.keep)} unchanged", not changed, changed)
            for path in case.absent:
                path = path.format(**subst)
                check(f"{label}: no {os.path.basename(path)}", not os.path.exists(path), path)
            check(f"{label}: no temporary file", not tmp, tmp)
            if case.check:
                good, detail = CHECKS[case.check](files, out)
                check(f"{label}: {case.check}", good, detail)
    leftover = temporaries(w)
    check("no temporary file in the work folder", not leftover, leftover)
    changed = [k for k, h in before.items() if sha(inputs[k]) != h]
    check("no generated input changed checksum in any case", not changed, changed)
    print(f"{len(cases)} cases in {time.time() - start:.1f} s")
    return summary()


if __name__ == "__main__":
    sys.exit(main())
