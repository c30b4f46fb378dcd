#!/usr/bin/env bash
# Installs everything gs-ibl needs on a fresh Debian/Ubuntu machine; safe to run again.
# - the Vulkan loader, Mesa lavapipe (a CPU Vulkan device, used when there is no GPU driver) and the shader tools
# - a venv in .venv with the pinned packages of requirements.txt
# - the SPIR-V shaders, rebuilt when a GLSL source is newer
set -euo pipefail
cd "$(dirname "$0")/.."
need=()
command -v glslc >/dev/null || need+=(glslc)
[ -e /usr/share/vulkan/icd.d/lvp_icd.x86_64.json ] || [ -e /usr/share/vulkan/icd.d/lvp_icd.json ] || \
  ls /usr/share/vulkan/icd.d/lvp_icd.*.json >/dev/null 2>&1 || need+=(mesa-vulkan-drivers)
ldconfig -p | grep libvulkan.so.1 >/dev/null || need+=(libvulkan1)  # not grep -q: SIGPIPE under pipefail
command -v spirv-val >/dev/null || need+=(spirv-tools)
if [ ${#need[@]} -gt 0 ]; then
  echo "[setup] installing system packages: ${need[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
fi
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.requirements.sha
want=$(sha1sum requirements.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "[setup] installing Python packages (bpy is large: a few minutes the first time)"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -r requirements.txt
  # bpy's wheel tag reads as 'not supported on this platform' to pip check; real conflicts still fail
  problems=$(.venv/bin/python -m pip check 2>&1 | grep -v -e 'is not supported on this platform' -e '^No broken' || true)
  if [ -n "$problems" ]; then echo "[setup] pip check: $problems" >&2; exit 1; fi
  echo "$want" > "$stamp"
fi
.venv/bin/python scripts/build_shaders.py
echo "[setup] ready"
