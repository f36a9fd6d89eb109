#!/usr/bin/env bash
# Installs today's renderers as Python modules in a virtual environment:
# Blender 5 (PyPI bpy 5.0.1, Cycles) and Mitsuba 3 (PyPI mitsuba, CPU variants),
# plus numpy<2 (bpy's add-ons are built against numpy 1.x) and OpenEXR.
#
#   experiments/setup_renderers.sh [VENV]     (default: $RENDER_VENV, else /work/venv-render)
#
# Idempotent: a venv that already imports everything at the pinned versions is left alone.
set -euo pipefail

venv=${1:-${RENDER_VENV:-/work/venv-render}}
# bpy 5.0.1's wheels are built for CPython 3.11: Debian 12's interpreter.
python=${RENDER_PYTHON:-/usr/bin/python3.11}
packages=("bpy==5.0.1" "mitsuba>=3.6,<4" "numpy<2" "OpenEXR>=3.2")

check() {
  "$venv/bin/python" - <<'EOF' 2>/dev/null
import bpy, mitsuba, numpy, OpenEXR
assert bpy.app.version[:2] == (5, 0), bpy.app.version
assert int(numpy.__version__.split(".")[0]) < 2, numpy.__version__
mitsuba.set_variant("scalar_rgb")
print(f"blender {bpy.app.version_string}, mitsuba {mitsuba.__version__}, numpy {numpy.__version__}")
EOF
}

# Mitsuba's llvm_ad_rgb variant (1.8x faster than scalar_rgb for the training
# frames of scenegen/mitsuba_gen.py) needs LLVM 17-19; Debian 12's 15 and 16 fail.
if command -v apt-get >/dev/null && [[ $(id -u) == 0 ]] && ! ldconfig -p | grep -q libLLVM-19; then
  apt-get install -y -q libllvm19 >/dev/null || echo "setup_renderers.sh: no libllvm19: Mitsuba runs scalar_rgb" >&2
fi
if [[ -x "$venv/bin/python" ]] && check; then
  exit 0
fi
if [[ ! -x "$python" ]]; then
  echo "setup_renderers.sh: $python not found (bpy 5.0.1 needs CPython 3.11; set RENDER_PYTHON)" >&2
  exit 1
fi
[[ -x "$venv/bin/python" ]] || "$python" -m venv "$venv"
"$venv/bin/python" -m pip install -q --upgrade pip
"$venv/bin/python" -m pip install -q "${packages[@]}"
check || { echo "setup_renderers.sh: $venv: the installed renderers do not import" >&2; exit 1; }
