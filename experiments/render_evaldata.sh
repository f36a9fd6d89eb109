#!/usr/bin/env bash
# Renders the evaluation sets from today's renderers (issues 22 and 23):
#   OUT/blender5/<scene>/{spp4,spp16,spp64,ref}.exr       Blender 5 Cycles, multi-part, full pass names
#   OUT/mitsuba_box/<scene>/{spp4,spp16,spp64,ref}.exr    Mitsuba 3, box filter (uncorrelated noise)
#   OUT/mitsuba_gauss/<scene>/{spp4,spp16,spp64,ref}.exr  Mitsuba 3, default Gaussian filter (splatted)
#
#   experiments/render_evaldata.sh [OUT]      (default: $EVALDATA, else /work/evaldata)
#   make -C experiments evaldata EVALDATA=OUT
#
# Settings from the environment: RES (192x192), BLENDER_REF_SPP (1024), MITSUBA_REF_SPP (512),
# SPPS ("4 16 64"), THREADS (2), RENDER_VENV (/work/venv-render), ONLY (some SET/SCENE jobs).
# Every noisy render comes first, then the references (the slow part: about 5 CPU-minutes for
# each Blender one, 1.7 for each Mitsuba one). Resumable: finished files are kept, a render is
# written under a temporary name.
set -euo pipefail

out=${1:-${EVALDATA:-/work/evaldata}}
res=${RES:-192x192}
blender_ref_spp=${BLENDER_REF_SPP:-1024}
mitsuba_ref_spp=${MITSUBA_REF_SPP:-512}
read -r -a spps <<<"${SPPS:-4 16 64}"
threads=${THREADS:-2}
venv=${RENDER_VENV:-/work/venv-render}
here=$(cd "$(dirname "$0")" && pwd)

blender_scenes=(cornell window hdri product exterior)
mitsuba_scenes=(cornell matpreview interior lanterns)

"$here/setup_renderers.sh" "$venv"
py="$venv/bin/python"

# One job: "SET SCENE"; its command renders that scene's files of one phase.
jobs=()
if [[ -n ${ONLY:-} ]]; then  # e.g. ONLY="mitsuba_gauss/lanterns blender5/exterior": these, in this order
  for job in $ONLY; do jobs+=("${job%%/*} ${job#*/}"); done
else
  for s in "${mitsuba_scenes[@]}"; do jobs+=("mitsuba_gauss $s" "mitsuba_box $s"); done
  for s in "${blender_scenes[@]}"; do jobs+=("blender5 $s"); done
fi
total=$((2 * ${#jobs[@]}))

command_for() {  # SET SCENE DIR: the renderer's command line, without the sample counts
  case $1 in
    blender5) echo "$py $here/render_blender5.py --scene $2 --out $3 --res $res --threads $threads" ;;
    mitsuba_box) echo "$py $here/render_mitsuba.py --scene $2 --filter box --out $3 --res $res --threads $threads" ;;
    mitsuba_gauss) echo "$py $here/render_mitsuba.py --scene $2 --filter gaussian --out $3 --res $res --threads $threads" ;;
  esac
}

step=0
run_phase() {  # PHASE: noisy or ref
  local phase=$1 set scene dir files args
  for job in "${jobs[@]}"; do
    read -r set scene <<<"$job"
    step=$((step + 1))
    dir="$out/$set/$scene"
    if [[ $phase == noisy ]]; then
      files=(); for n in "${spps[@]}"; do files+=("$dir/spp$n.exr"); done
      args=(--spp "${spps[@]}" --ref-spp 0)
    else
      files=("$dir/ref.exr")
      args=(--spp --ref-spp "$([[ $set == blender5 ]] && echo "$blender_ref_spp" || echo "$mitsuba_ref_spp")")
    fi
    local missing=0
    for f in "${files[@]}"; do [[ -f $f ]] || missing=1; done
    if ((missing == 0)); then
      echo "render_evaldata: [$step/$total] $set/$scene $phase: done already"
      continue
    fi
    echo "render_evaldata: [$step/$total] $set/$scene $phase: rendering ($(date -u +%H:%M:%S))"
    local start=$SECONDS
    # shellcheck disable=SC2046  # the command line is split on purpose
    $(command_for "$set" "$scene" "$dir") "${args[@]}" 2>&1 | grep -E 'render_(blender5|mitsuba): |Error|error' || true
    for f in "${files[@]}"; do
      [[ -f $f ]] || { echo "render_evaldata: $f was not written" >&2; exit 1; }
    done
    echo "render_evaldata: [$step/$total] $set/$scene $phase: $((SECONDS - start)) s"
  done
}

run_phase noisy
run_phase ref
echo "render_evaldata: all done in $out"
