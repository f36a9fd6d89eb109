#!/usr/bin/env python3
"""Installs the build into a prefix inside the build folder, then builds the
project in tests/consumer against it twice, with find_package(DiffusionDenoise)
and with pkg-config alone, runs the programs and checks their numbers: the
scores equal the installed dnmetrics's, the installed model measures less
noise in the converged reference than in the 4-spp render, and a 3-frame
sequence with motion vectors denoised through dn::temporal uses its
neighbours and equals the installed dndenoise's result bit for bit."""
import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(__file__))
from cli_checks import check, run, summary  # noqa: E402

# One thread in the consumer's LibTorch, as dndenoise --threads 1 runs.
ONE_THREAD = dict(os.environ, OMP_NUM_THREADS="1")


def must(cmd, what, env=None):
    """Runs cmd; a failure ends the check (what follows depends on it)."""
    out = run(cmd, env=env)
    check(what, out.returncode == 0, (out.stdout + out.stderr)[-3000:])
    if out.returncode != 0:
        sys.exit(summary())
    return out


def values(text):
    """'name value' lines as a dict."""
    return {k: v for k, v in (line.split(" ", 1) for line in text.splitlines() if " " in line)}


def shot(args):
    return os.path.join(args.source, "testdata", "sequence", "spp4.#.exr")


def check_sequence(args, prefix, program, name):
    """Frames 1-3 of testdata/sequence through dn::temporal, against the
    installed dndenoise on the same frames; returns the program's lines."""
    import numpy as np
    from exr_numpy import read_rgb

    work = args.work_dir
    out = must([program, shot(args), "1-3", os.path.join(work, name + ".#.exr")],
               "consumer sequence runs", ONE_THREAD)
    lines = out.stdout.splitlines()
    rows = [line.split() for line in lines]
    three = [r[1] for r in rows if len(r) == 6] == ["1", "2", "3"]
    check("consumer sequence denoises 3 frames", three, out.stdout)
    if not three:
        return lines
    middle = dict(zip(rows[1][::2], rows[1][1::2]))
    check(f"the middle frame uses its neighbours ({middle['neighbours']}, "
          f"{100 * float(middle['history']):.0f}% from history)",
          int(middle["neighbours"]) >= 2 and float(middle["history"]) > 0, out.stdout)
    must([os.path.join(prefix, "bin", "dndenoise"), shot(args), "--frames", "1-3", "--threads", "1",
          "--rgb-only", "--float", "-o", os.path.join(work, "dndenoise.#.exr")],
         "installed dndenoise denoises the same frames")
    for frame in (1, 2, 3):
        got = read_rgb(os.path.join(work, f"{name}.{frame:04d}.exr"))
        expected = read_rgb(os.path.join(work, f"dndenoise.{frame:04d}.exr"))
        diff = float(np.max(np.abs(got - expected)))
        check(f"frame {frame}: dn::temporal equals dndenoise (max difference {diff:.3g})", diff == 0)
    return lines


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", required=True)
    ap.add_argument("--source", required=True)
    ap.add_argument("--work-dir", required=True)
    ap.add_argument("--with-torch", default="1")
    ap.add_argument("--launcher", default="")
    args = ap.parse_args()
    work = args.work_dir
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    prefix = os.path.join(work, "prefix")
    torch = args.with_torch == "1"
    example = os.path.join(args.source, "testdata", "example")
    render, ref = os.path.join(example, "scene000201_4spp.exr"), os.path.join(example, "scene000201_ref.exr")

    must(["cmake", "--install", args.build, "--prefix", prefix], "cmake --install into a fresh prefix")
    installed = ["bin/dnmetrics", "include/dn/metrics.h", "include/dn/io/preview_io.h",
                 "lib/cmake/DiffusionDenoise/DiffusionDenoiseConfig.cmake", "lib/pkgconfig/dn-metrics.pc",
                 "share/diffusion_denoise/ocio/srgb.ocio", "share/doc/diffusion_denoise/docs/dndenoise.md"]
    if torch:
        installed += ["bin/dndenoise", "bin/dntrain", "bin/dncleanse", "include/dn/infer/denoiser.h",
                      "share/diffusion_denoise/models/default.dnm", "share/diffusion_denoise/models/isik.pt",
                      "lib/pkgconfig/dn-denoise.pc", "include/dn/temporal/sequence.h",
                      "lib/pkgconfig/dn-temporal.pc"]
    missing = [f for f in installed if not os.path.exists(os.path.join(prefix, f))]
    check("the tools, headers, package files, docs and models are installed", not missing, missing)

    # find_package(DiffusionDenoise) and the dn:: targets.
    build = os.path.join(work, "consumer-build")
    configure = ["cmake", "-S", os.path.join(args.source, "tests", "consumer"), "-B", build,
                 f"-DCMAKE_PREFIX_PATH={prefix}", f"-DWITH_DENOISE={'ON' if torch else 'OFF'}",
                 "-DCMAKE_BUILD_TYPE=Release"]
    if shutil.which("ninja"):
        configure += ["-G", "Ninja"]
    if args.launcher:
        configure.append(f"-DCMAKE_CXX_COMPILER_LAUNCHER={args.launcher}")
    must(configure, "consumer: find_package(DiffusionDenoise) configures")
    must(["cmake", "--build", build, "-j2"], "consumer: builds against dn::io, dn::metrics" +
         (", dn::denoise and dn::temporal" if torch else ""))

    score = values(must([os.path.join(build, "score"), ref, render], "consumer score runs").stdout)
    out = must([os.path.join(prefix, "bin", "dnmetrics"), "--format", "json", "--metrics", "l1,psnr", ref, render],
               "installed dnmetrics runs")
    expected = json.loads(out.stdout)["results"][0]
    for metric in ("l1", "psnr"):
        got = float(score.get(metric, "nan"))
        check(f"consumer {metric} {got:.6g} equals dnmetrics's {expected[metric]:.6g}",
              abs(got - expected[metric]) <= 1e-6 * abs(expected[metric]), score)

    if torch:
        noise = values(must([os.path.join(build, "noise"), render, ref], "consumer noise runs").stdout)
        noisy, converged = float(noise.get("noisy", "nan")), float(noise.get("converged", "nan"))
        check(f"installed model: noise of the 4-spp render ({noisy:.4g}) over twice the reference's "
              f"({converged:.4g})", noisy > 2 * converged > 0, noise)
        frames = check_sequence(args, prefix, os.path.join(build, "sequence"), "seq")

    # pkg-config alone, as a Makefile would use it.
    if not shutil.which("pkg-config"):
        return summary()
    env = dict(os.environ, PKG_CONFIG_PATH=os.path.join(prefix, "lib", "pkgconfig"))
    compiler = shlex.split(args.launcher) + [os.environ.get("CXX", "c++")]

    def pkg_build(source, modules, output, extra=()):
        flags = must(["pkg-config", "--cflags", "--libs"] + modules, f"pkg-config {' '.join(modules)}", env).stdout
        must(compiler + ["-std=c++17", "-O1", *extra, os.path.join(args.source, "tests", "consumer", source),
                         "-o", output] + shlex.split(flags), f"c++ {source} with pkg-config {' '.join(modules)}")

    pkg_build("score.cpp", ["dn-io", "dn-metrics"], os.path.join(work, "score-pc"))
    out = must([os.path.join(work, "score-pc"), ref, render], "pkg-config score runs")
    check("pkg-config score prints the same numbers", values(out.stdout) == score, out.stdout)
    if torch:
        model_dir = os.path.join(prefix, "share", "diffusion_denoise", "models")
        pkg_build("noise.cpp", ["dn-denoise"], os.path.join(work, "noise-pc"), [f'-DDN_MODEL_DIR="{model_dir}"'])
        out = must([os.path.join(work, "noise-pc"), render, ref], "pkg-config noise runs")
        check("pkg-config noise prints the same numbers", values(out.stdout) == noise, out.stdout)
        pkg_build("sequence.cpp", ["dn-temporal", "dn-denoise"], os.path.join(work, "sequence-pc"),
                  [f'-DDN_MODEL_DIR="{model_dir}"'])
        out = must([os.path.join(work, "sequence-pc"), shot(args), "1-3",
                    os.path.join(work, "seq-pc.#.exr")], "pkg-config sequence runs", ONE_THREAD)
        check("pkg-config sequence prints the same numbers", out.stdout.splitlines() == frames, out.stdout)
    return summary()


if __name__ == "__main__":
    sys.exit(main())
