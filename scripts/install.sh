#!/usr/bin/env bash
# Installs every dependency from Debian 12 packages and PyPI, then configures
# and builds the project into ./build (Release). Safe to run again.
#   DN_SKIP_BLENDER=1  skip Blender (only the scene generator needs it; the
#                      preview tests then skip Blender's Filmic)
#   DN_PREFIX=/opt/dn  also install the tools, libraries, models and docs there
#   DN_BPY_VENV=DIR    where the venv with bpy and openjd goes (default
#                      ./build-venv-bpy) for the Blender extension's and the
#                      farm template's tests
set -euo pipefail
cd "$(dirname "$0")/.."

sudo_if_needed() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

packages=(build-essential cmake ninja-build pkg-config git
          libtorch-dev libopenimageio-dev openimageio-tools libopenexr-dev
          libopencolorio-dev libfmt-dev doctest-dev libgloo-dev nlohmann-json3-dev
          blender-data  # Blender's OpenColorIO config (Filmic), for display pictures and their tests
          python3 python3-pip python3-venv)
[ "${DN_SKIP_BLENDER:-0}" = 1 ] || packages+=(blender mate-backgrounds)  # scene generator + its textures

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "install.sh: installing ${missing[*]}" >&2
  sudo_if_needed apt-get update -qq
  sudo_if_needed env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# Python tools used only to measure against (reference FLIP, OIDN, SSIM checks).
pip_packages=(numpy flip-evaluator pyoidn scikit-image OpenEXR)
if ! python3 -c "import numpy, flip_evaluator, pyoidn, skimage, OpenEXR" 2>/dev/null; then
  python3 -m pip install -q "${pip_packages[@]}" 2>/dev/null ||
    python3 -m pip install -q --break-system-packages "${pip_packages[@]}"
fi

# Blender as a Python module and the Open Job Description CLI, for the tests of
# blender/ and farm/: a venv of their own, as bpy 5.0.1 needs Python 3.11 and numpy<2.
bpy_venv=$(realpath -m "${DN_BPY_VENV:-build-venv-bpy}")
bpy_packages=("bpy==5.0.1" "numpy<2" "openjd-cli==0.8.0")
if ! "$bpy_venv/bin/python" -c "from importlib.metadata import version as v
assert v('bpy') == '5.0.1' and v('openjd-cli') == '0.8.0' and int(v('numpy').split('.')[0]) < 2" 2>/dev/null
then
  echo "install.sh: installing ${bpy_packages[*]} into $bpy_venv" >&2
  python3 -m venv "$bpy_venv"
  "$bpy_venv/bin/python" -m pip install -q "${bpy_packages[@]}"
fi

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DDN_BPY_VENV="$bpy_venv" >/dev/null
cmake --build build -j"$(nproc)"
if [ -n "${DN_PREFIX:-}" ]; then
  cmake --install build --prefix "$DN_PREFIX" >/dev/null
  echo "install.sh: installed into $DN_PREFIX (tools in $DN_PREFIX/bin)" >&2
fi
