#!/usr/bin/env bash
# Installs everything gs-ibl needs on a fresh Debian/Ubuntu machine; safe to run again.
# - from apt, when missing: the Vulkan loader, Mesa lavapipe (a CPU Vulkan device, used when there is no GPU
#   driver), the shader compiler, the X/GL libraries the bpy module links against, and a Python with venv:
#   3.11 (bpy 5.0.1: Debian 12, Ubuntu 22.04), else 3.13 (bpy 5.3.0: Debian 13), else python3 with the core alone
#   (no bpy wheel for it: the Blender parts are skipped, saying so)
# - with --node (scripts/test.sh): node and npm, for the format tests' PlayCanvas splat-transform
# - a venv in .venv with the pinned packages of requirements.txt (its markers pick the set for the venv's Python),
#   made again when its Python is not the one chosen here
# - the SPIR-V shaders, rebuilt only when a GLSL source changed
# PYTHON=... picks the interpreter instead.
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
LDCONFIG=$(command -v ldconfig || echo /sbin/ldconfig)
with_node=0; [ "${1:-}" = "--node" ] && with_node=1

have_pkg() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
py_ok() { command -v "$1" >/dev/null && "$1" -c "import venv, ensurepip" >/dev/null 2>&1; }
apt_updated=0
apt_install() {  # apt_install PKG...: --no-install-recommends, so the same set everywhere; errors shown
  if [ $apt_updated -eq 0 ]; then $SUDO apt-get update -qq; apt_updated=1; fi
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "$@" >/dev/null
}

need=()
command -v glslc >/dev/null || need+=(glslc)
ls /usr/share/vulkan/icd.d/lvp_icd.*.json >/dev/null 2>&1 || need+=(mesa-vulkan-drivers)
"$LDCONFIG" -p | grep libvulkan.so.1 >/dev/null || need+=(libvulkan1)  # not grep -q: SIGPIPE under pipefail
for p in libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libxxf86vm1 libsm6 libgl1 libegl1; do
  have_pkg "$p" || need+=("$p")
done
if [ ${#need[@]} -gt 0 ]; then
  echo "[setup] installing system packages: ${need[*]}"
  apt_install "${need[@]}"
fi
if [ $with_node -eq 1 ] && ! { command -v node >/dev/null && command -v npm >/dev/null; }; then
  echo "[setup] installing node and npm (for the splat-transform comparison tests)"
  apt_install nodejs npm 2>/dev/null || echo "[setup] apt could not install nodejs npm: those tests will be skipped" >&2
fi

# The Python: bpy wheels exist for one Python each (bpy 5.0.1: 3.11, bpy 5.3.0: 3.13; see requirements.txt).
PY=${PYTHON:-}
if [ -z "$PY" ]; then
  for v in 3.11 3.13; do py_ok "python$v" && { PY=python$v; break; }; done
fi
if [ -z "$PY" ]; then  # Debian 12 and Ubuntu 22.04 have 3.11 in apt, Debian 13 has 3.13, Ubuntu 24.04 neither
  for v in 3.11 3.13; do
    apt_install "python$v" "python$v-venv" >/dev/null 2>&1 && py_ok "python$v" && { PY=python$v; break; }
  done
fi
if [ -z "$PY" ]; then
  py_ok python3 || apt_install python3 python3-venv
  PY=python3
fi
want=$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
case "$want" in
  3.11|3.13) ;;
  *) echo "[setup] WARNING: Python $want has no bpy wheel (bpy 5.0.1 is built for Python 3.11 only, 5.3.0 for 3.13" \
          "only): installing the core without Blender; the Blender tests and the demo's Blender render will be skipped" >&2 ;;
esac

# A venv of another Python (a machine that gained 3.11 or 3.13), or whose pip does not run (an interrupted first
# run), is made again.
have=$(.venv/bin/python -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null || true)
if [ "$have" != "$want" ] || ! .venv/bin/python -m pip --version >/dev/null 2>&1; then
  echo "[setup] creating .venv with $PY ($("$PY" --version 2>&1))"
  rm -rf .venv
  "$PY" -m venv .venv
fi
stamp=.venv/.requirements.sha
sha=$(sha1sum requirements.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$sha" ]; then
  echo "[setup] installing Python packages (bpy is large: a few minutes the first time)"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -r requirements.txt
  # bpy's wheel tag reads as 'not supported on this platform' to pip check; real conflicts still fail
  problems=$(.venv/bin/python -m pip check 2>&1 | grep -v -e 'is not supported on this platform' -e '^No broken' || true)
  if [ -n "$problems" ]; then echo "[setup] pip check: $problems" >&2; exit 1; fi
  echo "$sha" > "$stamp"
fi
.venv/bin/python scripts/build_shaders.py
echo "[setup] ready"
