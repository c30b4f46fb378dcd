"""F12's mesh depth, its two parts side by side: reading the render-visible meshes out of the evaluated depsgraph
(blender/render/frame.py _mesh_triangles: foreach_get of vertices and loop triangles, world transform, the casters'
areas) against rasterising them (core/render/mesh_depth.py mesh_depth at 1920x1080), in the same process, on one
grid mesh of 2 n^2 triangles filling 93 % of the frame. The ratio says whether a cache of the read meshes between
frames would pay (docs/final-frame.md section 10).

    .venv/bin/python benchmarks/f12_mesh_read_bench.py [--n 400] [--rounds 3]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def grid_object(bpy, n: int):
    xs = np.linspace(-1, 1, n + 1)
    gx, gz = np.meshgrid(xs, xs)
    v = np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], 1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    f = np.stack([i, i + 1, i + n + 2, i + n + 1], -1).reshape(-1, 4)
    me = bpy.data.meshes.new("Grid")
    me.vertices.add(len(v))
    me.vertices.foreach_set("co", v.ravel())
    me.loops.add(f.size)
    me.loops.foreach_set("vertex_index", f.ravel())
    me.polygons.add(len(f))
    me.polygons.foreach_set("loop_start", np.arange(0, f.size, 4))
    me.update()
    ob = bpy.data.objects.new("Grid", me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=400, help="grid side in quads (2 n^2 triangles)")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    import bpy

    import gs_ibl_addon
    bpy.ops.wm.read_factory_settings(use_empty=True)
    gs_ibl_addon.register()
    from gs_ibl_addon.blender.render import frame
    from gs_ibl_addon.core.render.mesh_depth import mesh_depth
    grid_object(bpy, a.n)
    dg = bpy.context.evaluated_depsgraph_get()
    cam = np.eye(4)
    cam[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # at y = -3 looking along +y
    cam[:3, 3] = (0, -3, 0)
    print("| round | triangles | read ms | raster 1920x1080 ms | read / raster |\n|---|---|---|---|---|")
    for k in range(a.rounds):
        t0 = time.perf_counter()
        tris, _casters, _albedo = frame._mesh_triangles(dg)
        t1 = time.perf_counter()
        mesh_depth(tris, cam, 0.36, 0.2025, 1920, 1080)
        t2 = time.perf_counter()
        print(f"| {k} | {len(tris):,} | {1e3 * (t1 - t0):.0f} | {1e3 * (t2 - t1):.0f} | {(t1 - t0) / (t2 - t1):.2f} |")
    gs_ibl_addon.unregister()


if __name__ == "__main__":
    main()
