#!/usr/bin/env python3
"""dndenoise's display pictures against OpenColorIO's own transform: -o out.png
and --preview, with the built-in sRGB config and with Blender's config (Filmic),
compared with `oiiotool --ociodisplay` applied to the same denoised linear
result; 16-bit TIFF, $OCIO, frame sequences, wrong names, and progress written
as plain lines when stderr is not a terminal. A tiny model trained in seconds
stands in for the shipped one."""
import argparse
import os
import pty
import re
import shutil
import subprocess
import sys

try:
    sys.path.insert(0, os.path.dirname(__file__))
    from cli_checks import check, expect_error, run, summary
except ImportError as e:  # CTest reports this as skipped
    print(f"skipped: {e}")
    sys.exit(77)

BLENDER_CONFIG = "/usr/share/blender/datafiles/colormanagement/config.ocio"


def max_difference(a, b):
    """Largest per-channel difference of two images in code values of a's type, from idiff."""
    out = run(["idiff", "-v", "-a", "-abs", "-fail", "1", "-warn", "1", a, b])
    m = re.search(r"Max error\s*=\s*([0-9.eE+-]+)", out.stdout)
    if out.returncode not in (0, 1, 2) or not ("PASS" in out.stdout or m):
        return float("inf")
    if not m:  # identical images print no error statistics
        return 0.0
    levels = 65535 if a.endswith(".tif") else 255
    return float(m.group(1)) * levels


def stderr_on_terminal(cmd, env):
    """What cmd writes to stderr when stderr is a pseudo-terminal (which turns "\\n" into "\\r\\n")."""
    master, slave = pty.openpty()
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=slave, env=env)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    proc.wait()
    os.close(master)
    return b"".join(chunks).decode(errors="replace")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--source", required=True)
    ap.add_argument("--work-dir", required=True)
    args = ap.parse_args()
    if not shutil.which("oiiotool") or not shutil.which("idiff"):
        print("skipped: oiiotool and idiff (openimageio-tools) are needed")
        return 77
    w = args.work_dir
    shutil.rmtree(w, ignore_errors=True)
    os.makedirs(w)
    p = lambda *n: os.path.join(w, *n)  # noqa: E731
    dntrain, dndenoise = os.path.join(args.bin, "dntrain"), os.path.join(args.bin, "dndenoise")
    srgb_config = os.path.join(args.source, "libtonemap", "ocio", "srgb.ocio")
    env = {k: v for k, v in os.environ.items() if k != "OCIO"}

    out = run([sys.executable, os.path.join(os.path.dirname(__file__), "make_tiny_dataset.py"), p("data"),
               "--size", "48", "--frames", "1"])
    if out.returncode != 0:
        print(f"skipped: no tiny data set ({out.stderr.strip()[-200:]})")
        return 77
    tiny = ["--data", p("data"), "--batch", "2", "--crop", "16", "--threads", "1", "--spp", "4,16",
            "--val-every", "0"]
    run([dntrain, "base", "--out", p("base.dnm"), "--steps", "2", "--base-channels", "8", "--res-blocks", "1"]
        + tiny)
    out = run([dntrain, "control", "--base", p("base.dnm"), "--out", p("tiny.dnm"), "--steps", "2"] + tiny)
    check("a tiny model to denoise with", out.returncode == 0, out.stderr[-2000:])
    if out.returncode != 0:
        return summary()

    frame = os.path.join(p("data"), "val", "scene_0", "frame_0", "spp4_00.exr")
    denoise = [dndenoise, "--model", p("tiny.dnm"), "--steps", "6", "--skip", "2", "--threads", "1"]

    # One run: the linear result (float, alone) and its sRGB preview.
    out = run(denoise + ["-v", frame, "-o", p("linear.exr"), "--rgb-only", "--float", "--preview", p("preview.png")],
              env=env)
    check("dndenoise -o EXR --preview PNG: exit 0, both written",
          out.returncode == 0 and os.path.exists(p("linear.exr")) and os.path.exists(p("preview.png")), out.stderr)
    check("-v names the transform", "pictures through sRGB / Standard (OCIO config built-in sRGB)" in out.stderr,
          out.stderr)
    progress = [line for line in out.stderr.splitlines() if re.search(r"\[1/1\]\s+\d+%", line)]
    check("-v off a terminal: plain progress lines, no carriage returns",
          "\r" not in out.stderr and 2 <= len(progress) <= 11, out.stderr)

    # On a terminal the same progress is one line redrawn in place.
    tty_err = stderr_on_terminal(denoise + ["-v", frame, "-o", p("tty.exr")], env)
    check("-v on a terminal: the progress line is redrawn with carriage returns",
          len(re.findall("\r(?!\n)", tty_err)) >= 2 and "[1/1] 100%" in tty_err, repr(tty_err))

    # OpenColorIO through OpenImageIO on the same linear result.
    run(["oiiotool", p("linear.exr"), "--colorconfig", srgb_config, "--ociodisplay:from=lin_rec709", "sRGB",
         "Standard", "-d", "uint8", "-o", p("oiio_srgb.png")])
    d = max_difference(p("preview.png"), p("oiio_srgb.png"))
    check(f"--preview equals oiiotool --ociodisplay sRGB Standard (max {d:g} code values)", d <= 1, d)

    # -o PNG alone: the same picture (same seed).
    out = run(denoise + [frame, "-o", p("direct.png")], env=env)
    check("dndenoise -o PNG: exit 0 (was: 'PNG only supports 1-4 channels')", out.returncode == 0, out.stderr)
    d = max_difference(p("direct.png"), p("preview.png"))
    check(f"-o PNG equals the --preview picture (max {d:g})", d == 0, d)

    # 16-bit TIFF.
    out = run(denoise + [frame, "-o", p("direct.tif")], env=env)
    run(["oiiotool", p("linear.exr"), "--colorconfig", srgb_config, "--ociodisplay:from=lin_rec709", "sRGB",
         "Standard", "-d", "uint16", "-o", p("oiio_srgb.tif")])
    d = max_difference(p("direct.tif"), p("oiio_srgb.tif"))
    check(f"-o TIFF: 16-bit, equals oiiotool's (max {d:g} of 65535)", out.returncode == 0 and d <= 1, out.stderr)

    if os.path.exists(BLENDER_CONFIG):
        filmic = ["--ocio", BLENDER_CONFIG, "--view", "Filmic"]
        out = run(denoise + [frame, "-o", p("filmic.png")] + filmic, env=env)
        run(["oiiotool", p("linear.exr"), "--colorconfig", BLENDER_CONFIG, "--ociodisplay:from=Linear", "sRGB",
             "Filmic", "-d", "uint8", "-o", p("oiio_filmic.png")])
        d = max_difference(p("filmic.png"), p("oiio_filmic.png"))
        check(f"Blender's config, Filmic: equals oiiotool --ociodisplay sRGB Filmic (max {d:g})",
              out.returncode == 0 and d <= 1, out.stderr)
        check("Filmic differs from Standard", max_difference(p("filmic.png"), p("preview.png")) > 2)
        out = run(denoise + [frame, "-o", p("env.png"), "--view", "Filmic"], env=dict(env, OCIO=BLENDER_CONFIG))
        check("$OCIO is honoured", out.returncode == 0 and max_difference(p("env.png"), p("filmic.png")) == 0,
              out.stderr)
        out = run([dndenoise, "--ocio", BLENDER_CONFIG, "--list-views"], env=env)
        check("--list-views lists Blender's views", out.returncode == 0 and "sRGB / Filmic" in out.stdout, out.stdout)
    else:
        print(f"note: {BLENDER_CONFIG} not found (Debian package blender-data, which scripts/install.sh installs): Filmic checks skipped")

    # A frame sequence with a preview per frame.
    for n in (1, 2):
        shutil.copy(frame, p(f"shot.{n:04d}.exr"))
    os.makedirs(p("seq"))
    os.makedirs(p("prev"))
    out = run(denoise + [p("shot.#.exr"), "-o", p("seq", "out.#.exr"), "--preview", p("prev")], env=env)
    made = sorted(os.listdir(p("seq"))) + sorted(os.listdir(p("prev")))
    check("a sequence gets an EXR and a preview per frame", out.returncode == 0 and made == [
        "out.0001.exr", "out.0002.exr", "out.0001.png", "out.0002.png"], f"{made} {out.stderr}")
    expect_error("--preview of one file for a sequence",
                 denoise + [p("shot.#.exr"), "-o", p("seq", "again.#.exr"), "--preview", p("one.png")],
                 "--preview: several outputs need an existing folder", p("seq", "again.0001.exr"))

    # Wrong names fail at once, before any denoising, with nothing written.
    expect_error("--view that the config lacks", denoise + [frame, "-o", p("bad1.png"), "--view", "AgX"],
                 "display 'sRGB' has no view 'AgX' (it has: Standard, Raw)", p("bad1.png"))
    expect_error("--ocio of a missing file", denoise + [frame, "-o", p("bad2.png"), "--ocio", p("none.ocio")],
                 p("none.ocio"), p("bad2.png"))
    expect_error("--preview as EXR", denoise + [frame, "-o", p("x.exr"), "--preview", p("bad3.exr")],
                 "--preview takes a PNG, JPEG or TIFF picture or a folder", p("x.exr"))
    expect_error("--view without a picture", denoise + [frame, "-o", p("y.exr"), "--view", "Standard"],
                 "--view apply to PNG, JPEG or TIFF outputs", p("y.exr"))
    return summary()


if __name__ == "__main__":
    sys.exit(main())
