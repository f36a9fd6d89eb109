#!/usr/bin/env python3
"""The GPU check's results against OIDN's and against issue 53's targets: reads
the key=value lines check_cuda.sh collected (denoise_npy_bench, temporal_npy_bench
and oidn_bench.py RESULT lines without the word RESULT) and prints one line per
comparison. Python's standard library only.

  python3 bench/gpu/summarize.py RESULTS.txt
"""
import sys

# (our mode, OIDN's mode, the most ours may take, in OIDN's times)
TARGETS = [("default", "prefilter", 1.0), ("prefilter", "prefilter", 1.0), ("base", "usual", 1.0),
           ("control", "prefilter", 5.0)]


def parse(path):
    rows = []
    with open(path) as f:
        for line in f:
            if line.startswith("#") or "=" not in line:
                continue
            rows.append(dict(field.split("=", 1) for field in line.split() if "=" in field))
    return rows


def as_shipped(row, precision):
    """A run with the settings a user gets: TF32 and the benchmark mode on, the
    default memory budget."""
    return (row.get("tool") != "oidn" and row.get("mode") != "temporal" and row.get("device") != "cpu"
            and row.get("precision") == precision and row.get("tf32") == "on"
            and row.get("cudnn_benchmark") == "on" and row.get("memory_gb", "0") == "0")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    rows = parse(sys.argv[1])
    oidn = {(r["size"], r["mode"]): float(r["median_s"]) for r in rows if r.get("tool") == "oidn"}
    sizes = sorted({r["size"] for r in rows if "size" in r}, key=lambda s: [int(v) for v in s.split("x")])
    if not oidn:
        print("no OIDN lines (bench/gpu/check_cuda.sh --oidn adds them): times alone")
    for size in sizes:
        for precision in ("float", "fp16"):
            ours = {r["mode"]: r for r in rows if r.get("size") == size and as_shipped(r, precision)}
            for mode, oidn_mode, most in TARGETS:
                if mode not in ours:
                    continue
                seconds = float(ours[mode]["median_s"])
                agreement = ours[mode].get("psnr_vs_cpu", "-")
                line = f"{size} {mode} {precision}: {seconds:.4f} s, {agreement} dB against the CPU"
                if (size, oidn_mode) in oidn:
                    ratio = seconds / oidn[(size, oidn_mode)]
                    verdict = "met" if ratio <= most else "not met"
                    line += (f"; OIDN {oidn_mode} {oidn[(size, oidn_mode)]:.4f} s: {ratio:.2f}x "
                             f"(target <= {most:g}x: {verdict})")
                print(line)
    for r in rows:
        if r.get("mode") == "temporal":
            ratio = float(r["ratio"])
            # Lines before filter_path was written: the filter ran on the CPU.
            path = r.get("filter_path", "cpu")
            where = "on the CPU" if path == "cpu" else f"as tensors on {r.get('filter_device', r['device'])}"
            agreement = (f", {r['filter_psnr_db']} dB against the CPU's" if "filter_psnr_db" in r else "")
            print(f"{r['size']} temporal {r['precision']} on {r['device']}: {float(r['median_s']):.4f} s a frame, "
                  f"frame by frame {float(r['alone_s']):.4f} s: {ratio:.2f}x (target <= 1.3x: "
                  f"{'met' if ratio <= 1.3 else 'not met'}; the filter {float(r['filter_s']):.4f} s {where}"
                  f"{agreement})")


if __name__ == "__main__":
    main()
