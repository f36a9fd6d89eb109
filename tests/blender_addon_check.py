#!/usr/bin/env python3
"""The Blender extension (blender/) end to end with bpy 5.0.1 and the real
dndenoise: `python3 blender/build.py` builds the zip, Blender's own extension
tool validates it, and blender_addon_bpy.py installs it in bpy, prepares a tiny
animated Cycles scene, renders it at 4 and 256 spp, and denoises it through
the Denoise operator headless. Here: Prepare set the properties and said what
it changed, the result is an image sequence in the compositor, every frame
beats the noisy render against the 256-spp one (PSNR, read back with the
OpenEXR bindings), each bad input is one line with the denoised frames left
untouched, and a scene without the Vector pass is reported before and after
rendering.

  blender_addon_check.py --venv DIR --dndenoise BIN --source DIR --work-dir DIR
"""
import argparse
import json
import os
import shutil
import sys
import time
import tomllib
import zipfile

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cli_checks import check, run, summary  # noqa: E402

FRAMES = (1, 2, 3)


def read_layer(path, layer):
    """RGB of `layer` (e.g. ViewLayer.Combined) from any part of a multi-part EXR."""
    with OpenEXR.File(path, separate_channels=True) as f:
        for part in f.parts:
            if f"{layer}.R" in part.channels:
                return np.dstack([part.channels[f"{layer}.{c}"].pixels.astype(np.float64) for c in "RGB"])
    raise ValueError(f"{path}: no layer {layer}")


def psnr(a, ref):
    a, ref = np.clip(a, 0, 1), np.clip(ref, 0, 1)
    return 10 * np.log10(1 / np.mean((a - ref) ** 2))


def check_runner(dndenoise, source, work):
    """blender/runner.py as the modal operator drives it: polled from a timer, with
    progress, and cancelled (Esc) without leaving a partial frame."""
    sys.path.insert(0, os.path.join(source, "blender"))
    import runner
    seq = runner.sequence_from_paths("/r/shot_0009_b.exr", 9, "/r/shot_0010_b.exr", [9, 10])
    check("frame paths from frame_path -> pattern", seq.printf() == "/r/shot_%04d_b.exr" and
          seq.frame_range() == "9-10", seq.printf())
    shot = runner.sequence_of(os.path.join(source, "testdata", "sequence"))
    check("a folder -> its sequence", shot.frames == [1, 2, 3, 4, 5, 6], shot.frames)
    shot.frames = [1, 2, 3]
    out = runner.output_sequence(os.path.join(work, "polled", "den.####.exr"), shot.frames)
    os.makedirs(os.path.join(work, "polled"))
    job = runner.Job(runner.command(dndenoise, shot, out, "fast", threads=2), 3)
    fractions = []
    while not job.poll():
        time.sleep(0.05)
        fractions.append(job.fraction)
    check("polled like the modal timer: progress rises to the end, no error",
          job.error() is None and job.fraction == 1.0 and fractions == sorted(fractions), job.lines[-3:])
    check("and wrote the 3 frames", sorted(os.listdir(os.path.join(work, "polled"))) ==
          [f"den.{n:04d}.exr" for n in (1, 2, 3)])
    out = runner.output_sequence(os.path.join(work, "cancelled", "den.####.exr"), shot.frames)
    os.makedirs(os.path.join(work, "cancelled"))
    job = runner.Job(runner.command(dndenoise, shot, out, "high", threads=2), 3)
    while not job.poll() and not any("[1/3]" in line for line in job.lines):
        time.sleep(0.01)
    job.cancel()
    job.wait()
    left = os.listdir(os.path.join(work, "cancelled"))
    check("cancelled: one line, no unfinished file", (job.error() or "").startswith("dndenoise cancelled") and
          all(n.startswith("den.") and n.endswith(".exr") for n in left), (job.error(), left))


def passes_sum_error(path):
    """Largest relative difference of Cycles' rule over the Denoised passes from the Denoised beauty."""
    with OpenEXR.File(path, separate_channels=True) as f:
        ch = {n: c.pixels.astype(np.float64) for p in f.parts for n, c in p.channels.items()}

    def D(name):
        key = f"ViewLayer.Denoised {name}".rstrip()
        return np.dstack([ch[f"{key}.{c}"] for c in "RGB"]) if f"{key}.R" in ch else 0.0
    total = D("Residual")
    for kind in ("Diffuse", "Glossy", "Transmission"):
        total = total + (D(kind + " Direct") + D(kind + " Indirect")) * D(kind + " Color")
    for name in ("Volume Direct", "Volume Indirect", "Emission", "Environment"):
        total = total + D(name)
    beauty = D("")
    return float((np.abs(total - beauty) / np.maximum(np.abs(beauty), 1e-3)).max())


def main():
    ap = argparse.ArgumentParser()
    for a in ("--venv", "--dndenoise", "--source", "--work-dir"):
        ap.add_argument(a, required=True)
    args = ap.parse_args()
    work = os.path.abspath(args.work_dir)
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    python = os.path.join(args.venv, "bin", "python")
    if not os.path.exists(python):
        sys.exit(f"FAIL: no bpy venv at {args.venv} (scripts/install.sh makes it; DN_BPY_VENV)")

    # The zip: manifest and package at its root, as Blender 4.2+ installs it.
    out = run([sys.executable, os.path.join(args.source, "blender", "build.py"), "--output-dir", work])
    zip_path = out.stdout.strip()
    with open(os.path.join(args.source, "blender", "blender_manifest.toml"), "rb") as manifest:
        version = tomllib.load(manifest)["version"]
    check("build.py builds build/dn_denoise-<version>.zip", out.returncode == 0 and
          os.path.basename(zip_path) == f"dn_denoise-{version}.zip", out.stderr)
    names = zipfile.ZipFile(zip_path).namelist()
    check("the zip holds the manifest and __init__.py at its root, not build.py",
          {"blender_manifest.toml", "__init__.py"} <= set(names) and "build.py" not in names, names)
    out = run([python, "-c", "import bpy; print(bpy.utils.system_resource('SCRIPTS'))"])
    tool = os.path.join(out.stdout.strip().splitlines()[-1], "addons_core", "bl_pkg", "cli", "blender_ext.py")
    out = run([python, tool, "validate", zip_path])
    check("Blender's extension tool validates the zip", out.returncode == 0, out.stdout + out.stderr)
    native = os.path.join(work, "native")
    os.makedirs(native)
    out = run([python, tool, "build", "--source-dir", os.path.join(args.source, "blender"), "--output-dir", native])
    built = os.path.join(native, os.path.basename(zip_path))
    check("and builds a zip of the same files from blender/", out.returncode == 0 and os.path.exists(built) and
          sorted(zipfile.ZipFile(built).namelist()) == sorted(names), out.stdout + out.stderr)

    check_runner(os.path.abspath(args.dndenoise), args.source, work)

    # Blender's user folders in the work dir: the install must not touch ~/.config.
    env = dict(os.environ, BLENDER_USER_RESOURCES=os.path.join(work, "user"))
    start = time.time()
    out = run([python, os.path.join(os.path.dirname(os.path.abspath(__file__)), "blender_addon_bpy.py"),
               "--zip", zip_path, "--dndenoise", os.path.abspath(args.dndenoise), "--work-dir", work,
               "--out", os.path.join(work, "seen.json")], env=env)
    print(f"bpy part: {time.time() - start:.1f} s")
    if out.returncode != 0:
        sys.exit(f"FAIL: the bpy part exited {out.returncode}\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}")
    seen = json.load(open(os.path.join(work, "seen.json")))
    print(f"renders {seen['render_seconds']:.1f} s, Denoise operator {seen['denoise_seconds']:.1f} s")

    check("the zip installs and enables in bpy", seen["install"] == [["FINISHED"], ""], seen["install"])
    check("Check before Prepare names the missing Vector pass", "Vector pass is off" in seen["check_before"],
          seen["check_before"])
    check("Prepare reports what it changed", seen["prepare"][0] == ["FINISHED"] and
          seen["prepare_status"].startswith("prepared: "), seen["prepare_status"])
    expected = {"view_layer.use_pass_vector": True, "view_layer.cycles.denoising_store_passes": True,
                "view_layer.use_pass_glossy_direct": True, "view_layer.use_pass_transmission_color": True,
                "scene.cycles.use_animated_seed": True, "scene.cycles.use_denoising": False,
                "scene.render.use_motion_blur": False, "image_settings.media_type": "MULTI_LAYER_IMAGE",
                "image_settings.file_format": "OPEN_EXR_MULTILAYER"}
    check("Prepare set the passes (glossy and transmission for Temporal), seed, motion blur and multilayer EXR",
          seen["properties"] == expected,
          seen["properties"])
    check("Check after Prepare: ready", seen["check_after"] == "ready for dndenoise", seen["check_after"])
    check("Prepare again changes nothing", seen["prepare_again"] == "already prepared: nothing changed",
          seen["prepare_again"])
    check("progress lines from dndenoise -v reach the console",
          any(line.startswith("dndenoise: ") and line.endswith("%") for line in out.stdout.splitlines()),
          out.stdout[-2000:])

    check("Denoise finished", seen["denoise"] == [["FINISHED"], ""], seen["denoise"])
    den = os.path.join(work, "den")
    check("Denoise wrote the 3 frames", sorted(os.listdir(den)) == [f"shot.{n:04d}.exr" for n in FRAMES],
          os.listdir(den))
    image = seen["image"] or {}
    check("the result is loaded as an image sequence",
          image.get("filepath") == os.path.join(den, "shot.0001.exr") and image.get("type") == "MULTILAYER", image)
    check("and put in the compositor's dndenoise node", seen["compositor_image"] == image.get("name", ""),
          seen["compositor_image"])
    for n in FRAMES:
        name = f"shot.{n:04d}.exr"
        ref = read_layer(os.path.join(work, "ref", name), "ViewLayer.Combined")
        noisy = psnr(read_layer(os.path.join(work, "noisy", name), "ViewLayer.Combined"), ref)
        denoised = psnr(read_layer(os.path.join(den, name), "ViewLayer.Denoised"), ref)
        check(f"frame {n}: denoised {denoised:.2f} dB > noisy {noisy:.2f} dB + 3 against 256 spp",
              denoised > noisy + 3)

    # Bad inputs: one line each, and the frames denoised above untouched.
    bad = seen["bad"]
    for case, words in (("no_dndenoise", "dndenoise not found at"), ("too_old", "needs 0.1.0 or newer"),
                        ("missing_frames", "missing frame 4"), ("not_a_sequence", "not a frame sequence")):
        line = bad[case]
        check(f"{case}: one line ({line})", words in line and "\n" not in line, line)
    check("bad inputs overwrote nothing", seen["den_after_bad"] == seen["den_before_bad"])

    check("no Vector pass: Check says so before rendering", "Vector pass is off" in seen["novec_check"],
          seen["novec_check"])
    check("no Vector pass: Denoise finishes with dndenoise's frame-by-frame line as a warning",
          seen["novec_denoise"] == [["FINISHED"], ""] and "frame by frame" in seen["novec_status"],
          seen["novec_status"])

    check("Light Passes: Prepare adds the 7 light passes Temporal's 6 lacked and the Vector pass back",
          seen["passes_prepare"] == "prepared: 8 settings changed", seen["passes_prepare"])
    passes_den = os.path.join(work, "passes_den", "shot.0002.exr")
    with OpenEXR.File(passes_den) as f:
        layers = {p.name() for p in f.parts}
    check("Light Passes: Denoise writes them denoised beside the noisy ones",
          seen["passes_denoise"] == [["FINISHED"], ""] and
          {"ViewLayer.Denoised Diffuse Direct", "ViewLayer.Denoised Glossy Color", "ViewLayer.Diffuse Direct"}
          <= layers, (seen["passes_denoise"], sorted(layers)))
    rel = passes_sum_error(passes_den)
    check(f"Light Passes with Temporal: the denoised passes add up to the denoised beauty ({rel:.1e})",
          rel < 1e-5, rel)
    return summary()


if __name__ == "__main__":
    sys.exit(main())
