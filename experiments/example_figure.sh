#!/usr/bin/env bash
# The before/after pictures at the top of docs/dndenoise.md: the shipped
# example (256x256, 4 spp), dndenoise's result with the shipped model and the
# 1024-spp reference, all through the display transform dndenoise writes PNGs
# with (the built-in sRGB config, libtonemap/ocio/srgb.ocio). The result's
# picture is dndenoise's own --preview; the render and the reference go
# through the same config with oiiotool (tests/preview_check.py checks that the
# two agree).
#   experiments/example_figure.sh [BUILD_DIR]      (default: build; minutes with the current model)
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-build}/bin"
out=docs/images
config=libtonemap/ocio/srgb.ocio
example=testdata/example/scene000201
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

# The render's colour, as dndenoise reads it (ViewLayer.Combined), to sRGB.
to_display() {
  oiiotool "$1" --ch ViewLayer.Combined.R,ViewLayer.Combined.G,ViewLayer.Combined.B \
    --chnames R,G,B --colorconfig "$config" --ociodisplay:from=lin_rec709 sRGB Standard \
    -d uint8 -o "$2"
}
to_display "${example}_4spp.exr" "$out/example_noisy.png"
to_display "${example}_ref.exr" "$out/example_reference.png"
env -u OCIO "$bin/dndenoise" -v "${example}_4spp.exr" -o "$work/denoised.exr" \
  --preview "$out/example_denoised.png"
"$bin/dnmetrics" --metrics l1,psnr,flip "${example}_ref.exr" "${example}_4spp.exr" "$work/denoised.exr"
