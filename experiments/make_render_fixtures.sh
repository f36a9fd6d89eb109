#!/usr/bin/env bash
# Small renders from today's renderers for the tests (testdata/renderers/, half floats, ZIP):
#   blender5_hdri_4spp.exr + blender5_hdri_ref.exr            Blender 5.0.1 Cycles, a 64x64 crop of the
#                                                             192x192 'hdri' scene, multi-part, full pass names
#   mitsuba_box_matpreview_4spp.exr + ..._ref.exr             Mitsuba 3 'matpreview', 96x96, box filter
#   mitsuba_gauss_cornell_4spp.exr + ..._ref.exr              Mitsuba 3 'cornell', 96x96, Gaussian filter
# References: 2048 spp. About 5 CPU-minutes.
#
#   experiments/make_render_fixtures.sh [OUT]     (default: testdata/renderers)
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
out=${1:-$here/../testdata/renderers}
venv=${RENDER_VENV:-/work/venv-render}
threads=${THREADS:-2}
"$here/setup_renderers.sh" "$venv" >/dev/null
py="$venv/bin/python"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"

render() {  # NAME RENDERER-ARGS...: renders NAME's 4 spp and reference into OUT
  local name=$1
  shift
  if [[ -f $out/${name}_4spp.exr && -f $out/${name}_ref.exr ]]; then
    return
  fi
  "$py" "$@" --out "$tmp/$name" --spp 4 --ref-spp 2048 --threads "$threads" --half 2>&1 |
    grep -E 'render_(blender5|mitsuba): ' || true
  mv "$tmp/$name/spp4.exr" "$out/${name}_4spp.exr"
  mv "$tmp/$name/ref.exr" "$out/${name}_ref.exr"
}

render blender5_hdri "$here/render_blender5.py" --scene hdri --res 192x192 --border 0.2917,0.2084,0.625,0.5417
render mitsuba_box_matpreview "$here/render_mitsuba.py" --scene matpreview --filter box --res 96x96
render mitsuba_gauss_cornell "$here/render_mitsuba.py" --scene cornell --filter gaussian --res 96x96
ls -l "$out"
