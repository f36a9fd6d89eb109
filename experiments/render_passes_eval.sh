#!/usr/bin/env bash
# Evaluation renders with every Cycles light pass, for the denoised passes
# (issue 33; docs/RESULTS.md#denoised-light-passes). Small and niced:
#  - Blender 3.4 (Debian's `blender`, scenegen/generate.py): test-split seeds
#    at 128x128, 16 stacks of 4 spp (16 and 64 spp are means of 4 and 16
#    stacks, as experiments/make_inputs.py makes them), one 512-spp reference;
#  - Blender 5 (PyPI bpy, experiments/render_blender5.py --all-light-passes):
#    scenes at 128x128, 4/16/64 spp, 512-spp reference, multi-part files.
#
#   experiments/render_passes_eval.sh [OUT]   (default /work/data/passes/renders)
# Resumable: finished files are skipped. PASSES_ONLY=b34 or b5 renders one part
# (the two can run side by side).
set -euo pipefail
out=${1:-/work/data/passes/renders}
here=$(cd "$(dirname "$0")" && pwd)
root=$(dirname "$here")
seeds=${PASSES_SEEDS:-"2 3"}
gt_spp=${PASSES_GT_SPP:-512}
b5_scenes=${PASSES_B5_SCENES:-"hdri cornell"}
b5_ref_spp=${PASSES_B5_REF_SPP:-512}
venv=${RENDER_VENV:-/work/data/passes/venv-render}
mkdir -p "$out/b34" "$out/b5"

jobs="$out/b34/jobs.json"
python3 - "$jobs" "$out/b34" $seeds <<'PY'
import json, sys
path, folder, seeds = sys.argv[1], sys.argv[2], sys.argv[3:]
json.dump([{"seed": int(s), "scene_dir": f"{folder}/scene_{int(s):06d}", "frames": [0]} for s in seeds],
          open(path, "w"))
PY
only=${PASSES_ONLY:-all}
if [[ $only != b5 ]]; then
  nice -n 10 blender -b --factory-startup --python "$root/scenegen/generate.py" -- --jobs "$jobs" \
      --res 128 --spp 4 --stacks 16 --gt-spp "$gt_spp" --gt-count 1 --threads 1 --codec ZIP
fi

if [[ $only == b34 ]]; then
  :
elif [[ -x "$venv/bin/python" ]]; then
  for scene in $b5_scenes; do
    nice -n 10 "$venv/bin/python" "$here/render_blender5.py" --scene "$scene" --out "$out/b5/$scene" \
        --res 128x128 --spp 4 16 64 --ref-spp "$b5_ref_spp" --threads 1 --all-light-passes
  done
else
  echo "render_passes_eval.sh: no $venv (experiments/setup_renderers.sh $venv): Blender 5 renders skipped" >&2
fi
