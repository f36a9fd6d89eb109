#!/usr/bin/env bash
# Rebuilds testdata/ from the generator (about an hour on 2 cores). Steps already done are skipped.
#   pairs/    6 frames at 128x128: NAME_4spp.exr + NAME_ref.exr (1024 spp), all passes
#   example/  one fresh 256x256 frame: NAME_4spp.exr + NAME_ref.exr (1024 spp)
#   dataset/  miniature data set, same layout as the full one: seeds 300 (train), 304 (test),
#             314 (val); 2 frames each, 64x64, 4 stacks of 4 spp, 2 x 512-spp ground truth
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
td="$here/../testdata"
"$here/make_pairs.sh" "$td/pairs" 128 4 1024 101 102 103 104 105 106
python3 "$here/make_dataset.py" --out "$td/dataset" --seeds 300,304,314 --res 64 --spp 4 --stacks 4 \
  --gt-spp 512 --frames 2 --threads "${THREADS:-2}"
rm -rf "$td/dataset/logs"
"$here/make_pairs.sh" "$td/example" 256 4 1024 201
