#!/usr/bin/env bash
# Frames per hour of the scene generator on this machine, at data-set settings:
# 128x128, 16 stacks x 4 spp + 2 x 1024-spp ground truth, one Blender process per scene
# (all renders of all its frames in that process). Prints the split between GT and stacks.
# usage: bench/scenegen_bench.sh [SCENES=2] [FRAMES=2]   (env: RES SPP STACKS GT_SPP THREADS FIRST_SEED)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
scenes="${1:-2}"; frames="${2:-2}"
res="${RES:-128}"; spp="${SPP:-4}"; stacks="${STACKS:-16}"; gt_spp="${GT_SPP:-1024}"
threads="${THREADS:-2}"; first="${FIRST_SEED:-500}"
out="$(mktemp -d "${TMPDIR:-/tmp}/scenegen_bench.XXXXXX")"
trap 'rm -rf "$out"' EXIT
echo "scenegen bench: $scenes scenes x $frames frames, ${res}x${res}, $stacks x ${spp} spp + 2 x ${gt_spp} spp, $threads threads" >&2
start=$(date +%s.%N)
for ((s = first; s < first + scenes; s++)); do
  blender -b --factory-startup --python "$root/scenegen/generate.py" -- --seed "$s" \
    --scene-dir "$out/scene_$s" --res "$res" --spp "$spp" --stacks "$stacks" --gt-spp "$gt_spp" \
    --frames 8 --only-frames "$(seq -s, 0 $((frames - 1)))" --threads "$threads" >"$out/log_$s" 2>&1 ||
    { echo "scenegen_bench.sh: blender failed on seed $s:" >&2; tail -5 "$out/log_$s" >&2; exit 1; }
done
end=$(date +%s.%N)
# CPU seconds of the Blender children (user + sys): `times` must run in this shell, not a subshell.
times >"$out/times"
cpu=$(tail -1 "$out/times" | awk '{ for (i = 1; i <= 2; i++) { split($i, t, /[ms]/); s += 60 * t[1] + t[2] } print s }')
python3 - "$out" "$start" "$end" "$cpu" "$threads" <<'PY'
import glob, json, os, sys
out, start, end, cpu, threads = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
metas = [json.load(open(p)) for p in sorted(glob.glob(os.path.join(out, "scene_*", "frame_*", "meta.json")))]
wall = end - start
gt = sum(v for m in metas for k, v in m["render_seconds"].items() if k.startswith("gt"))
st = sum(v for m in metas for k, v in m["render_seconds"].items() if k.startswith("spp"))
frame_total = sum(m["frame_seconds"] for m in metas)
n = len(metas)
print("frames rendered:          %d (%d scenes)" % (n, len({m['seed'] for m in metas})))
print("wall time:                %.1f s  (%.1f s per frame)" % (wall, wall / n))
print("frames per hour:          %.1f" % (3600 * n / wall))
print("GT renders (2 per frame): %.1f s per frame (%.0f%% of wall)" % (gt / n, 100 * gt / wall))
print("stacks (%2d per frame):    %.1f s per frame (%.0f%% of wall), %.2f s per stack"
      % (metas[0]["stacks"], st / n, 100 * st / wall, st / n / metas[0]["stacks"]))
print("startup, scene build, exposure probe: %.1f s total (%.0f%% of wall)"
      % (wall - frame_total, 100 * (wall - frame_total) / wall))
# On a shared machine wall time depends on the load; CPU time does not (much).
print("CPU time:                 %.1f s (%.0f%% of %d threads busy)" % (cpu, 100 * cpu / (wall * threads), threads))
print("frames per hour if %d cores were free: %.1f" % (threads, 3600 * n / (cpu / threads)))
print("load average at the end:  %s" % open("/proc/loadavg").read().split()[0])
PY
