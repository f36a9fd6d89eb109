#!/usr/bin/env python3
"""dncleanse as a user meets it, on a tiny synthetic data set (seconds):
train, interrupt with SIGINT, resume to the same weights as an uninterrupted
run, apply to a data set (skip / --force), one-file mode, and every bad-input
case (one line on stderr naming the file, exit 1, no output file)."""
import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(__file__))
from exr_numpy import read_rgb, write_rgb  # noqa: E402
from cli_checks import check, expect_error, run, summary  # noqa: E402


# A small network and the buffers the synthetic frames have.
NET = ["--buffers", "albedo,normal", "--widths", "8,8", "--dilations", "1,2", "--feature-dims", "4"]
RUN = ["--batch", "2", "--crop", "16", "--threads", "1", "--lr", "3e-3"]




def write_frame(path, color, albedo, normal):
    channels = {}
    for layer, data, letters in (("Combined", color, "RGB"), ("Denoising Albedo", albedo, "RGB"),
                                 ("Denoising Normal", normal, "XYZ")):
        for i, letter in enumerate(letters):
            channels[f"ViewLayer.{layer}.{letter}"] = np.ascontiguousarray(data[:, :, i], np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(path)


def make_dataset(root, rng, size=24):
    """Two train scenes, one val scene; flat-coloured stripes with exponential noise."""
    for split, scenes in (("train", 2), ("val", 1)):
        for s in range(scenes):
            d = os.path.join(root, split, f"scene_{s:06d}", "frame_0")
            os.makedirs(d)
            colours = rng.random((4, 3)) * 1.5 + 0.1
            clean = np.repeat(colours, size // 4, axis=0)[None, :, :].repeat(size, axis=0)
            albedo = np.clip(clean / 1.6, 0, 1)
            normal = np.zeros_like(clean)
            normal[:, :, 2] = 1
            noisy = lambda: clean * rng.exponential(1.0, clean.shape)  # noqa: E731
            for name in ("gt_a", "gt_b", "spp4_00", "spp4_01"):
                write_frame(os.path.join(d, name + ".exr"), noisy(), albedo, normal)
            write_rgb(os.path.join(d, "truth.exr"), clean)  # not a data-set file: for scoring
            with open(os.path.join(d, "meta.json"), "w") as f:
                f.write("{}\n")



def log_events(path):
    with open(path) as f:
        return [json.loads(line) for line in f]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dncleanse", required=True)
    ap.add_argument("--work-dir", required=True)
    ap.add_argument("--oidn-model", help="models/oidn.dnm: apply cleanses with the pretrained base")
    args = ap.parse_args()
    tool, w = args.dncleanse, args.work_dir
    shutil.rmtree(w, ignore_errors=True)
    os.makedirs(w)
    p = lambda *n: os.path.join(w, *n)  # noqa: E731
    data = p("data")
    make_dataset(data, np.random.default_rng(5))

    # --- training, uninterrupted, with validation
    out = run([tool, "train", "--data", data, "--out", p("full.pt"), "--steps", "12",
               "--val-every", "6", "--val-samples", "2"] + RUN + NET)
    check("train: exit 0", out.returncode == 0, out.stderr)
    check("train: model, checkpoint and log written",
          all(os.path.exists(p(f)) for f in ("full.pt", "full.pt.ckpt", "full.pt.log.jsonl")))
    events = log_events(p("full.pt.log.jsonl"))
    kinds = [e["event"] for e in events]
    check("train: log has start, train, validation, checkpoint, done",
          all(k in kinds for k in ("start", "train", "validation", "checkpoint", "done")), str(kinds))
    check("train: log losses finite", all(np.isfinite(e["loss"]) for e in events if e["event"] == "train"))
    check("train: log the identity's loss beside the model's",
          all(np.isfinite(e["identity_loss"]) for e in events if e["event"] == "train")
          and all(e["identity_smape"] > 0 for e in events if e["event"] == "validation"))
    check("train: progress line on stderr", "step 12/12" in out.stderr, out.stderr)

    # --- the same run in two parts: --steps 5, then --resume to 12
    out = run([tool, "train", "--data", data, "--out", p("split.pt"), "--steps", "5"] + RUN + NET)
    check("train part 1: exit 0", out.returncode == 0, out.stderr)
    out = run([tool, "train", "--out", p("split.pt"), "--resume", "--steps", "12", "--threads", "1"])
    check("resume: exit 0", out.returncode == 0, out.stderr)
    check("resume: log says resume at step 5",
          {"event": "resume", "step": 5} in log_events(p("split.pt.log.jsonl")))
    src = os.path.join(data, "val", "scene_000000", "frame_0", "gt_a.exr")
    results = {}
    for name in ("full", "split"):
        out = run([tool, src, "-o", p(f"{name}.exr"), "--model", p(f"{name}.pt"), "--rgb-only"])
        check(f"one file with {name}.pt: exit 0", out.returncode == 0, out.stderr)
        results[name] = read_rgb(p(f"{name}.exr"))
    diff = float(np.abs(results["full"] - results["split"]).max())
    check("resumed run gives the uninterrupted run's model", diff < 1e-5, f"max difference {diff}")

    # --- SIGINT writes a checkpoint and exits 130; --resume continues from it
    proc = subprocess.Popen([tool, "train", "--data", data, "--out", p("sig.pt"), "--steps",
                             "100000"] + RUN + NET, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline:
        if os.path.exists(p("sig.pt.log.jsonl")) and '"train"' in open(p("sig.pt.log.jsonl")).read():
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    check("SIGINT: exit 130", proc.returncode == 130, f"exit {proc.returncode} {err!r}")
    stopped = [e for e in log_events(p("sig.pt.log.jsonl")) if e["event"] == "stopped"]
    check("SIGINT: checkpoint and model written, log says stopped",
          os.path.exists(p("sig.pt.ckpt")) and os.path.exists(p("sig.pt")) and len(stopped) == 1)
    if stopped:
        target = stopped[0]["step"] + 3
        out = run([tool, "train", "--out", p("sig.pt"), "--resume", "--steps", str(target),
                   "--threads", "1"])
        done = [e for e in log_events(p("sig.pt.log.jsonl")) if e["event"] == "done"]
        check("SIGINT: resume finishes at the new step count",
              out.returncode == 0 and done and done[-1]["step"] == target, out.stderr)

    # --- apply to the data set
    frames = [os.path.join(r, "gt_clean.exr") for r, _, fs in os.walk(data) if "meta.json" in fs]
    out = run([tool, "apply", "--model", p("full.pt"), "--data", data])
    check("apply: exit 0 and gt_clean.exr for every frame",
          out.returncode == 0 and all(os.path.exists(f) for f in frames), out.stderr)
    clean = read_rgb(frames[0])
    check("apply: finite RGB of the frame size", clean.shape == (24, 24, 3) and np.isfinite(clean).all())
    stamp = os.path.getmtime(frames[0])
    out = run([tool, "apply", "--model", p("full.pt"), "--data", data])
    check("apply again: skips existing", out.returncode == 0 and "skipped 3" in out.stderr
          and os.path.getmtime(frames[0]) == stamp, out.stderr)
    time.sleep(0.05)
    out = run([tool, "apply", "--model", p("full.pt"), "--data", data, "--force"])
    check("apply --force: rewrites", out.returncode == 0 and "wrote 3" in out.stderr, out.stderr)
    out = run([tool, "apply", "--model", p("full.pt"), "--data", data, "--force", "--split", "val"])
    check("apply --split val: the val frame only", out.returncode == 0 and "wrote 1 gt_clean.exr" in out.stderr, out.stderr)
    check("apply: no temporary files left",
          not any(".tmp" in f for _, _, fs in os.walk(data) for f in fs))

    # --- apply with the pretrained base: the mean of both ground truths, denoised
    if args.oidn_model:
        out = run([tool, "apply", "--model", args.oidn_model, "--data", data, "--source", "mean", "--force"])
        check("apply with the base: exit 0, wrote 3", out.returncode == 0 and "wrote 3" in out.stderr, out.stderr)
        errors = []
        for f in frames:
            d = os.path.dirname(f)
            truth = read_rgb(os.path.join(d, "truth.exr"))
            raw = 0.5 * (read_rgb(os.path.join(d, "gt_a.exr")) + read_rgb(os.path.join(d, "gt_b.exr")))
            errors.append((np.abs(read_rgb(f) - truth).mean(), np.abs(raw - truth).mean()))
        check("apply with the base: closer to the truth than the raw mean of both, on every frame",
              all(cleansed < 0.5 * raw for cleansed, raw in errors), str(errors))
        # Every buffer is averaged, so gt_b must have each one gt_a has.
        lone = p("lone")
        d = os.path.join(lone, "train", "scene_000000", "frame_0")
        os.makedirs(d)
        for name in ("gt_a", "gt_b"):
            shutil.copy(os.path.join(os.path.dirname(frames[0]), name + ".exr"), os.path.join(d, name + ".exr"))
        write_rgb(os.path.join(d, "gt_b.exr"), read_rgb(os.path.join(d, "gt_b.exr")))
        with open(os.path.join(d, "meta.json"), "w") as f:
            f.write("{}\n")
        expect_error("--source mean: gt_b lacks a buffer of gt_a",
                     [tool, "apply", "--model", args.oidn_model, "--data", lone, "--source", "mean"],
                     "gt_b.exr: has no albedo buffer", no_file=os.path.join(d, "gt_clean.exr"))
        expect_error("--source mean with a kernel model",
                     [tool, "apply", "--model", p("full.pt"), "--data", data, "--source", "mean"], "mean")

    # --- one file: a layer next to the input's layers; the input is untouched
    before = open(src, "rb").read()
    out = run([tool, src, "-o", p("layered.exr"), "--model", p("full.pt")])
    with OpenEXR.File(p("layered.exr")) as f:
        names = list(f.channels())
    check("one file: ViewLayer.Cleansed layer added to the input's layers",
          out.returncode == 0 and "ViewLayer.Cleansed" in names and "ViewLayer.Combined" in names,
          f"{out.stderr} {names}")
    check("one file: input unchanged", open(src, "rb").read() == before)

    # --- the Isik baseline: --task denoise, same tool
    out = run([tool, "train", "--data", data, "--out", p("isik.pt"), "--steps", "3", "--task",
               "denoise", "--spp", "4,8"] + RUN + NET)
    check("train --task denoise: exit 0", out.returncode == 0, out.stderr)
    noisy_in = os.path.join(data, "val", "scene_000000", "frame_0", "spp4_00.exr")
    out = run([tool, noisy_in, "-o", p("isik.exr"), "--model", p("isik.pt")])
    with OpenEXR.File(p("isik.exr")) as f:
        has_layer = "ViewLayer.Denoised" in f.channels()
    check("denoise model: writes a Denoised layer", out.returncode == 0 and has_layer, out.stderr)

    # --- bad input
    write_rgb(p("plain.exr"), np.ones((8, 8, 3), np.float32))
    with open(p("full.pt"), "rb") as f:
        model = bytearray(f.read())
    model[-50] ^= 0xFF
    with open(p("corrupt.pt"), "wb") as f:
        f.write(model)
    with open(p("garbage.exr"), "wb") as f:
        f.write(b"not an image at all")
    expect_error("missing model", [tool, src, "-o", p("x1.exr"), "--model", p("nope.pt")],
                 p("nope.pt"), p("x1.exr"))
    expect_error("corrupt model", [tool, src, "-o", p("x2.exr"), "--model", p("corrupt.pt")],
                 p("corrupt.pt"), p("x2.exr"))
    expect_error("diffusion checkpoint as model",
                 [tool, src, "-o", p("x3.exr"), "--model", p("full.pt.ckpt")], p("full.pt.ckpt"), p("x3.exr"))
    expect_error("input lacks the model's buffers",
                 [tool, p("plain.exr"), "-o", p("x4.exr"), "--model", p("full.pt")], p("plain.exr"), p("x4.exr"))
    expect_error("unreadable input", [tool, p("garbage.exr"), "-o", p("x5.exr"), "--model", p("full.pt")],
                 p("garbage.exr"), p("x5.exr"))
    expect_error("missing input", [tool, p("absent.exr"), "-o", p("x6.exr"), "--model", p("full.pt")],
                 p("absent.exr"), p("x6.exr"))
    expect_error("output over the input", [tool, src, "-o", src, "--model", p("full.pt")], src)
    check("output over the input: input unchanged", open(src, "rb").read() == before)
    expect_error("missing data set", [tool, "train", "--data", p("nodata"), "--out", p("y.pt")] + NET,
                 p("nodata"), p("y.pt"))
    expect_error("output folder missing", [tool, "train", "--data", data, "--out", p("no", "y.pt")],
                 p("no", "y.pt"))
    expect_error("resume without checkpoint", [tool, "train", "--out", p("fresh.pt"), "--resume"],
                 p("fresh.pt.ckpt"), p("fresh.pt"))
    expect_error("resume with another batch size",
                 [tool, "train", "--out", p("split.pt"), "--resume", "--batch", "4"], p("split.pt.ckpt"))
    expect_error("fresh run over an existing checkpoint",
                 [tool, "train", "--data", data, "--out", p("split.pt"), "--steps", "1"] + NET, p("split.pt.ckpt"))
    expect_error("apply with a denoise model", [tool, "apply", "--model", p("isik.pt"), "--data", data],
                 p("isik.pt"))
    expect_error("unknown buffer", [tool, "train", "--data", data, "--out", p("y.pt"), "--buffers", "nope"],
                 "nope", p("y.pt"))
    expect_error("demodulation without albedo",
                 [tool, "train", "--data", data, "--out", p("y.pt"), "--buffers", "normal"], "albedo", p("y.pt"))
    expect_error("bad --demodulate", [tool, "train", "--data", data, "--out", p("y.pt"), "--demodulate", "yes"],
                 "--demodulate", p("y.pt"))
    expect_error("unknown option", [tool, src, "-o", p("x7.exr"), "--model", p("full.pt"), "--bogus"],
                 "--bogus", p("x7.exr"))

    return summary()


if __name__ == "__main__":
    sys.exit(main())
