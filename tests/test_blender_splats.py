"""A million splats embedded in a .blend: save, reload, read back exactly; timings printed (pytest -s shows them)."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from gs_ibl_addon.blender.splats.object import PROXY_POINTS, create_splat_object, scene_from_object  # noqa: E402

from gs_ibl_addon.core.synthetic import random_scene  # noqa: E402


def test_million_splats_survive_save_and_reload(tmp_path):
    n = 1_000_000
    bpy.ops.wm.read_factory_settings(use_empty=True)
    src = random_scene(n, seed=7, sh_degree=3)
    t0 = time.perf_counter()
    obj = create_splat_object(bpy.context, src, "million")
    t_create = time.perf_counter() - t0
    obj.location = (0.5, -2.0, 1.0)
    bpy.context.view_layer.update()
    # the viewport proxy draws a bounded random subset, not every splat
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    geo = ev.evaluated_geometry()
    shown = len(geo.pointcloud.points)
    assert 0.9 * PROXY_POINTS < shown < 1.1 * PROXY_POINTS
    path = str(tmp_path / "million.blend")
    t0 = time.perf_counter()
    bpy.ops.wm.save_as_mainfile(filepath=path)
    t_save = time.perf_counter() - t0
    size_mb = os.path.getsize(path) / 1e6
    bpy.ops.wm.read_factory_settings(use_empty=True)
    t0 = time.perf_counter()
    bpy.ops.wm.open_mainfile(filepath=path)
    t_load = time.perf_counter() - t0
    obj = bpy.data.objects["million"]
    t0 = time.perf_counter()
    back = scene_from_object(obj)
    t_read = time.perf_counter() - t0
    want = src.transformed(np.array(obj.matrix_world))
    np.testing.assert_array_equal(back.sh, src.sh)
    np.testing.assert_array_equal(back.opacities, src.opacities)
    np.testing.assert_allclose(back.positions, want.positions, atol=1e-6)
    np.testing.assert_array_equal(back.scales, src.scales)
    print(f"\n1M splats, SH degree 3: create {t_create:.2f} s, save {t_save:.2f} s, {size_mb:.0f} MB .blend, "
          f"load {t_load:.2f} s, scene_from_object {t_read:.2f} s")
    # ~59 floats per splat + the display colour: the file is the data, nothing more
    assert size_mb < 300
