#!/bin/sh
# Renders the tiny cleansing experiment of docs/dncleanse.md ("Does cleansing help?"):
# DATA: RES x RES frames with ground truth at GT_SPP (gt_a, gt_b) and one 4-spp stack;
# REF: the validation frames again at REF_SPP (>= 8x GT_SPP); its gt_b.exr is the
# reference (Cycles seed independent of DATA's gt_a, which is what gets cleansed).
#   OUT=/tmp/cleanse_exp sh experiments/cleanse_tiny/render.sh
set -e
OUT=${OUT:-/tmp/cleanse_exp}
RES=${RES:-64}
GT_SPP=${GT_SPP:-64}
REF_SPP=${REF_SPP:-512}
VAL_SEEDS=${VAL_SEEDS:-"2000 2001 2002"}
TRAIN_SEEDS=${TRAIN_SEEDS:-"$(seq 1000 1010)"}
G=$(dirname "$0")/../../scenegen/generate.py
mkdir -p "$OUT/logs"
run() { blender -b --factory-startup --python "$G" -- "$@" > "$OUT/logs/blender_$1_$2.log" 2>&1; }
for s in $VAL_SEEDS; do
  run --seed $s --scene-dir "$OUT/data/val/scene_$s" --res $RES --spp 4 --stacks 1 \
      --gt-spp $GT_SPP --frames 8 --only-frames 0,4 --threads 2
  run --seed $s --scene-dir "$OUT/ref/val/scene_$s" --res $RES --spp 4 --stacks 0 \
      --gt-spp $REF_SPP --frames 8 --only-frames 0,4 --threads 2
  echo "val scene $s done $(date +%T)"
done
for s in $TRAIN_SEEDS; do
  run --seed $s --scene-dir "$OUT/data/train/scene_$s" --res $RES --spp 4 --stacks 1 \
      --gt-spp $GT_SPP --frames 8 --only-frames 0,2,4,6 --threads 2
  echo "train scene $s done $(date +%T)"
done
