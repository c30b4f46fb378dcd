#!/usr/bin/env bash
# Installs everything gs-ibl needs on a fresh Debian/Ubuntu machine; safe to run again.
# - the Vulkan loader, Mesa lavapipe (a CPU Vulkan device, used when there is no GPU driver), the shader compiler,
#   Python 3.11 with venv, and the X libraries the bpy module links against
# - a venv in .venv with the pinned packages of requirements.txt (bpy, Blender as a module, needs Python 3.11;
#   where no Python 3.11 can be had the core is installed without it and the Blender parts are skipped, saying so)
# - the SPIR-V shaders, rebuilt only when a GLSL source changed
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
LDCONFIG=$(command -v ldconfig || echo /sbin/ldconfig)

have_pkg() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
need=()
command -v glslc >/dev/null || need+=(glslc)
ls /usr/share/vulkan/icd.d/lvp_icd.*.json >/dev/null 2>&1 || need+=(mesa-vulkan-drivers)
"$LDCONFIG" -p | grep libvulkan.so.1 >/dev/null || need+=(libvulkan1)  # not grep -q: SIGPIPE under pipefail
for p in libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libxxf86vm1 libsm6 libgl1; do
  have_pkg "$p" || need+=("$p")
done
python3 -c "import venv, ensurepip" >/dev/null 2>&1 || need+=(python3-venv)
# bpy 5.0.1 is built for Python 3.11 only; Debian 12 and Ubuntu 22.04 have it in apt, Ubuntu 24.04 does not
want311=()
if [ -z "${PYTHON:-}" ] && ! { command -v python3.11 >/dev/null && python3.11 -c "import venv, ensurepip" 2>/dev/null; }; then
  want311=(python3.11 python3.11-venv)
fi
if [ ${#need[@]} -gt 0 ] || [ ${#want311[@]} -gt 0 ]; then
  $SUDO apt-get update -qq
fi
if [ ${#need[@]} -gt 0 ]; then
  echo "[setup] installing system packages: ${need[*]}"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
fi
if [ ${#want311[@]} -gt 0 ]; then
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${want311[@]}" >/dev/null 2>&1 \
    || echo "[setup] apt has no Python 3.11 here: the Blender parts (bpy) will be skipped" >&2
fi
PY=${PYTHON:-}
if [ -z "$PY" ]; then
  if command -v python3.11 >/dev/null; then PY=python3.11; else PY=python3; fi
fi

# A venv whose pip does not run (an interrupted first run) is made again.
if ! .venv/bin/python -m pip --version >/dev/null 2>&1; then
  echo "[setup] creating .venv with $PY ($("$PY" --version 2>&1))"
  rm -rf .venv
  "$PY" -m venv .venv
fi
req=requirements.txt
if ! .venv/bin/python -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
  echo "[setup] WARNING: $(.venv/bin/python --version) has no bpy 5.0.1 wheel (Python 3.11 only): installing the core" \
       "without Blender; the Blender tests and the demo's Blender render will be skipped" >&2
  grep -v '^bpy' requirements.txt > .venv/requirements-core.txt
  req=.venv/requirements-core.txt
fi
stamp=.venv/.requirements.sha
want=$(sha1sum "$req" | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "[setup] installing Python packages (bpy is large: a few minutes the first time)"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -r "$req"
  # bpy's wheel tag reads as 'not supported on this platform' to pip check; real conflicts still fail
  problems=$(.venv/bin/python -m pip check 2>&1 | grep -v -e 'is not supported on this platform' -e '^No broken' || true)
  if [ -n "$problems" ]; then echo "[setup] pip check: $problems" >&2; exit 1; fi
  echo "$want" > "$stamp"
fi
.venv/bin/python scripts/build_shaders.py
echo "[setup] ready"
