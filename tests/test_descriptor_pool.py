"""A kernel's descriptor pool that fills and is reset while a frame is being recorded (pipelines.py: the sets of
that pool are freed, the context's epoch moves on) must not leave the renderer with a program it cannot run: the
renderer records the frame again (the whole suite once hit 'recorded program is stale' in a bake this way)."""
from __future__ import annotations

import numpy as np

from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.synthetic import random_scene
from gs_ibl_addon.core.vk import pipelines


def test_frames_survive_a_pool_reset_while_recording(monkeypatch):
    scene = random_scene(3000, seed=5, sh_degree=1)
    sizes = (16, 24, 32, 40, 48, 56)
    with SplatRenderer(scene) as r:
        want = [np.array(r.render(ViewBatch.cubemap([0, 0, 0], s)).images) for s in sizes]
    # a pool of a few sets fills within a recording or two: every frame below meets a reset somewhere
    monkeypatch.setattr(pipelines.Pipeline, "POOL_SETS", 6)
    with SplatRenderer(scene) as r:
        for _ in range(2):
            for s, w in zip(sizes, want):
                got = np.array(r.render(ViewBatch.cubemap([0, 0, 0], s)).images)
                np.testing.assert_array_equal(got, w)
