#!/usr/bin/env bash
# The main job on the bundled sample scene: set everything up, bake a probe of samples/room.ply with the command
# line, write its images and a preview picture, then light meshes with it in Blender (Cycles) and render a frame.
# Everything lands in out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out/demo
.venv/bin/python -m gs_ibl_addon bake samples/room.ply --out out/demo/probe
if .venv/bin/python -c "import bpy" 2>/dev/null; then
  .venv/bin/python scripts/blender_demo.py --out out/demo/blender_render.png --blend out/demo/demo.blend
else
  echo "[demo] skipping the Blender render: bpy is not installed (it needs Python 3.11 or 3.13; see the setup output)" >&2
fi
echo "[demo] look at out/demo/probe/preview.png (radiance | irradiance | lit sphere) and out/demo/blender_render.png"
