#!/usr/bin/env bash
# The real-Blender matrix (tests/real_blender/test_matrix.py): makes the cached Blenders that are missing
# (scripts/blender_roots.sh, under /var/cache/gs-ibl), then installs the built zip in each and runs the scenario.
# Results, logs, renders and screenshots: build/matrix/<entry>/. Extra arguments go to pytest (e.g. -k bpy-4.2).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || bash scripts/setup.sh
mkdir -p build/matrix
t0=$SECONDS
# debootstrap once, before the roots are made side by side: two apt-get runs at once fail on apt's lock
if ! command -v debootstrap >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq debootstrap >/dev/null
fi
# The four are independent and mostly wait on the network: made side by side, each with its own log.
pids=()
for group in "sid" "trixie" "bpy42 bpy50"; do
  # shellcheck disable=SC2086
  bash scripts/blender_roots.sh ensure $group > "build/matrix/roots-${group// /-}.log" 2>&1 &
  pids+=($!)
done
failed=0
for p in "${pids[@]}"; do wait "$p" || failed=1; done
cat build/matrix/roots-*.log | grep '^\[roots\]' || true
if [ $failed -ne 0 ]; then
  echo "[matrix] making the Blenders failed: see build/matrix/roots-*.log" >&2
  tail -n 20 build/matrix/roots-*.log >&2
  exit 1
fi
echo "[matrix] Blenders ready in $((SECONDS - t0)) s"
GS_IBL_REQUIRE_MATRIX=1 .venv/bin/python -m pytest -q -s -p no:cacheprovider tests/real_blender "$@"
echo "[matrix] total $((SECONDS - t0)) s"
