"""Native Splats (issue 36 item 1): who draws Blender 5.3's Gaussian-splat Point Clouds in F12 (render/splats.py).

The bpy module here is 5.0, which has no native splats, so the render depsgraph's objects are stand-ins with the
attributes collect() reads (type, data.type, original, visible_camera, matrix_world). The same choice in a real
Blender 5.3, both engines, is tests/real_blender/test_native_choice.py.
"""
from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

pytest.importorskip("bpy")

from gs_ibl_addon.blender.render import splats  # noqa: E402


def native(name: str, camera: bool = True):
    """(the user's object, its evaluated copy in a render depsgraph)."""
    data = NS(type="GAUSSIAN_SPLAT")
    orig = NS(name=name, type="POINTCLOUD", data=data, visible_camera=camera)
    return orig, NS(name=name, type="POINTCLOUD", data=data, visible_camera=camera, original=orig)


def depsgraph(choice: str, *evaluated, instances: int = 1):
    m = np.identity(4)
    return NS(scene=NS(gs_ibl_render=NS(native_splats=choice)),
              object_instances=[NS(object=ev, matrix_world=m) for ev in evaluated for _ in range(instances)])


@pytest.fixture(autouse=True)
def new_job():
    splats.end_job()
    yield
    splats.end_job()


def test_gs_ibl_draws_them_and_hides_only_the_render_copy():
    orig, ev = native("guitar")
    ours, left = splats.collect(depsgraph("GSIBL", ev))
    assert [o for o, _ in ours] == [orig] and left == []
    splats.hide_taken()  # render_layers: their frame is drawn
    assert ev.visible_camera is False, "Blender's engine would draw it too"
    assert orig.visible_camera is True, "the user's object must not be written"


def test_a_frame_we_cannot_draw_leaves_them_to_blender():
    _orig, ev = native("guitar")
    splats.collect(depsgraph("GSIBL", ev))  # then the frame is refused before render_layers
    assert ev.visible_camera is True
    splats.collect(depsgraph("GSIBL"))  # the next view layer's frame holds none: nothing of the last is hidden
    splats.hide_taken()
    assert ev.visible_camera is True


def test_the_next_frame_of_a_persistent_render_still_draws_them():
    orig, ev = native("guitar")
    splats.collect(depsgraph("GSIBL", ev))
    splats.hide_taken()
    ours, _ = splats.collect(depsgraph("GSIBL", ev))  # the same evaluated copy, hidden by the first frame
    assert [o for o, _ in ours] == [orig]
    splats.end_job()
    orig2, ev2 = native("guitar", camera=False)  # a new job: what we hid before no longer counts
    assert splats.collect(depsgraph("GSIBL", ev2)) == ([], [])


def test_every_instance_of_one_copy_is_drawn():
    orig, ev = native("guitar")
    ours, _ = splats.collect(depsgraph("GSIBL", ev, instances=3))
    assert [o for o, _ in ours] == [orig] * 3


def test_camera_icon_off_is_left_out():
    _orig, ev = native("guitar", camera=False)
    assert splats.collect(depsgraph("GSIBL", ev)) == ([], [])


def test_blender_draws_them_untouched():
    _orig, ev = native("guitar")
    ours, left = splats.collect(depsgraph("BLENDER", ev))
    assert ours == [] and left == ["guitar"] and ev.visible_camera is True


def test_the_setting_and_its_default(blender):
    rs = blender.context.scene.gs_ibl_render
    assert rs.native_splats == "GSIBL"
    assert splats.draws_native(blender.context.scene)
    rs.native_splats = "BLENDER"
    assert not splats.draws_native(blender.context.scene)
    assert not splats.draws_native(NS())  # a scene without our settings (the extension not registered)
