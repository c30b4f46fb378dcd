#!/usr/bin/env bash
# Sets everything up, then runs the whole test suite (on lavapipe when there is no GPU).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --node     # --node: node and npm from apt when missing, for the next line
bash scripts/setup_node_tools.sh  # PlayCanvas splat-transform for tests/test_formats_ecosystem.py (needs node/npm)
if [ -n "${CI:-}" ]; then
  # CI must run the Blender half: a bpy that fails to import would otherwise only skip those tests
  .venv/bin/python -c "import bpy" || { echo "[test] bpy does not import: the Blender tests cannot run" >&2; exit 1; }
fi
exec .venv/bin/python -m pytest -q tests "$@"
