#!/usr/bin/env bash
# Blender 5 as a Python module (PyPI bpy 5.0.1, for Debian's Python 3.11) in its own
# virtual environment, for scenegen/ and experiments/ scripts that run under a Blender 5.
# bpy's add-ons need numpy < 2, so it cannot share the system's numpy.
#   scripts/install_bpy.sh [VENV]      default VENV: build-venv-bpy, as scripts/install.sh makes it (or $DN_BPY_VENV)
set -euo pipefail
venv="${1:-${DN_BPY_VENV:-build-venv-bpy}}"
if [ -x "$venv/bin/python" ] && "$venv/bin/python" -c "import bpy" 2>/dev/null; then
  echo "install_bpy.sh: $venv already has bpy $("$venv/bin/python" -c 'import bpy; print(bpy.app.version_string)')" >&2
  exit 0
fi
/usr/bin/python3.11 -m venv "$venv"
"$venv/bin/python" -m pip install -q "bpy==5.0.1" "numpy<2"
"$venv/bin/python" -c "import bpy; print('install_bpy.sh: bpy', bpy.app.version_string, 'in $venv')" >&2
