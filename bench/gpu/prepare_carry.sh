#!/usr/bin/env bash
# Run HERE (the development machine, default build done) before the GPU run:
# fills bench/gpu/carry/ (ignored by git; name it in the device tool's `carry`)
# with what the GPU machine lacks, then prints the size of what would travel.
#   example.npz  the shipped example's buffers as dndenoise reads them (it has
#                no OpenImageIO/OpenEXR to read the EXR itself)
#   doctest/     doctest's header and CMake package (for the core's tests)
#   oidn/        with --with-oidn: OIDN 2.5.1's core and CUDA device from the
#                pyoidn wheel, for OIDN's own CUDA timings (about 54 MB)
#   build/       with --cuda-build DIR: denoise_npy_bench, temporal_npy_bench,
#                test_device, test_npy, test_tiler and test_temporal_device
#                from a core build against the GPU machine's PyTorch wheel
#                (docs/dndenoise.md#gpu),
#                stripped, so that the GPU run skips its build
#
#   bash bench/gpu/prepare_carry.sh [--with-oidn] [--cuda-build DIR] [BUILD_DIR]
set -euo pipefail
cd "$(dirname "$0")/../.."
with_oidn=0
cuda_build=
build=build
while [ $# -gt 0 ]; do
  case "$1" in
    --with-oidn) with_oidn=1 ;;
    --cuda-build) cuda_build=$2; shift ;;
    *) build=$1 ;;
  esac
  shift
done
carry=bench/gpu/carry
rm -rf "$carry"
mkdir -p "$carry"

# The example's buffers, through the project's own reader.
cmake --build "$build" --target exr_to_npy >/dev/null
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# Every buffer: the Control Module's extra inputs too, so that its output is dndenoise's.
"$build/bin/exr_to_npy" testdata/example/scene000201_4spp.exr "$tmp" >/dev/null
python3 - "$tmp" "$carry/example.npz" <<'EOF'
import os, sys
import numpy as np
src, dst = sys.argv[1], sys.argv[2]
np.savez_compressed(dst, **{f[:-4]: np.load(os.path.join(src, f)) for f in sorted(os.listdir(src))})
EOF

# doctest (Debian: doctest-dev), relocatable: its config finds the header from its own place.
config=$(dirname "$(find /usr/lib /usr/share /usr/local -name doctestConfig.cmake -print -quit 2>/dev/null)")
header=$(find /usr/include /usr/local/include -path '*doctest/doctest.h' -print -quit 2>/dev/null)
if [ -n "$config" ] && [ -n "$header" ]; then
  mkdir -p "$carry/doctest/lib/cmake" "$carry/doctest/include"
  cp -r "$config" "$carry/doctest/lib/cmake/"
  cp -r "$(dirname "$header")" "$carry/doctest/include/"
  # Debian's doctestTargets.cmake names /usr outright: find the prefix from the file's place.
  sed -i 's|^set(_IMPORT_PREFIX "/usr")$|get_filename_component(_IMPORT_PREFIX "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)|' \
    "$carry/doctest/lib/cmake/doctest/doctestTargets.cmake"
else
  echo "prepare_carry: doctest not found here; the GPU run will build without the tests" >&2
fi

if [ "$with_oidn" = 1 ]; then
  lib=$(python3 -c 'import os, pyoidn; print(os.path.join(os.path.dirname(pyoidn.__file__), "oidn", "lib"))')
  mkdir -p "$carry/oidn"
  cp "$lib/libOpenImageDenoise.so.2" "$lib/libOpenImageDenoise_core.so.2.5.1" \
     "$lib/libOpenImageDenoise_device_cuda.so.2.5.1" "$carry/oidn/"
fi

if [ -n "$cuda_build" ]; then
  mkdir -p "$carry/build/bin"
  for program in denoise_npy_bench temporal_npy_bench test_device test_npy test_tiler test_temporal_device; do
    strip -o "$carry/build/bin/$program" "$cuda_build/bin/$program"
  done
  sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$cuda_build/CMakeCache.txt" >"$carry/build/source_dir"
  torch_dir=$(sed -n 's/^Torch_DIR:PATH=//p' "$cuda_build/CMakeCache.txt")  # torch/share/cmake/Torch
  sed -n "s/^__version__ = '\(.*\)'$/\1/p" "$torch_dir/../../../version.py" >"$carry/build/torch_version"
fi

# The commit the carry was made from, for the results file (a "+" when the tree had changes).
echo "$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- . ':!bench/gpu/carry' || echo +)" >"$carry/commit"

# What the device tool sends: tracked and untracked-not-ignored files, plus the carry.
tree=$( (git ls-files -z; git ls-files -z --others --exclude-standard) | xargs -0 du -cb 2>/dev/null | tail -1 | cut -f1)
extra=$(du -sb "$carry" | cut -f1)
total=$((tree + extra))
printf 'prepare_carry: %s: %d KiB; with the working tree (%d MiB) %d MiB travel (the limit is 64 MiB)\n' \
  "$carry" $((extra / 1024)) $((tree / 1048576)) $((total / 1048576))
if [ "$total" -gt $((64 * 1048576)) ]; then
  echo "prepare_carry: over 64 MiB: see docs/dndenoise.md#gpu for what to leave behind" >&2
fi
