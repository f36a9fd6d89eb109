#!/usr/bin/env bash
# Noisy/reference EXR pairs for metric tests and examples: frame 0 of fresh scenes,
# one low-spp render and one high-spp reference each, named NAME_<spp>spp.exr / NAME_ref.exr.
# usage: scenegen/make_pairs.sh OUT_DIR RES SPP REF_SPP SEED...
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="$1"; res="$2"; spp="$3"; ref_spp="$4"; shift 4
mkdir -p "$out"
work="$(mktemp -d "$out/.work.XXXXXX")"
trap 'rm -rf "$work"' EXIT
for seed in "$@"; do
  name="scene$(printf %06d "$seed")"
  if [[ -f "$out/${name}_${spp}spp.exr" && -f "$out/${name}_ref.exr" ]]; then continue; fi
  blender -b --factory-startup --python "$here/generate.py" -- --seed "$seed" \
    --scene-dir "$work/$name" --res "$res" --spp "$spp" --stacks 1 --gt-spp "$ref_spp" \
    --gt-count 1 --frames 8 --only-frames 0 --threads "${THREADS:-2}" >"$work/$name.log" 2>&1 ||
    { echo "make_pairs.sh: blender failed for seed $seed, log: $work/$name.log" >&2; tail -5 "$work/$name.log" >&2; exit 1; }
  mv "$work/$name/frame_0/spp${spp}_00.exr" "$out/${name}_${spp}spp.exr.tmp"
  mv "$work/$name/frame_0/gt_a.exr" "$out/${name}_ref.exr.tmp"
  mv "$out/${name}_${spp}spp.exr.tmp" "$out/${name}_${spp}spp.exr"
  mv "$out/${name}_ref.exr.tmp" "$out/${name}_ref.exr"
  echo "make_pairs.sh: $name done" >&2
done
