"""Our import below Blender 5.3 (the bpy module here is 5.0): Blender Splats is ignored and our mesh is made, a
native object cannot be asked for, and the panel names the object's file. Blender 5.3's native path runs in the
real-Blender matrix (tests/real_blender/scenario.py step_object_kind)."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from gs_ibl_addon.core.synthetic import random_scene


class _Layout:
    """Records the labels a panel draws; every other layout call is accepted and ignored."""

    def __init__(self, labels: list[str]):
        self.labels = labels

    def label(self, text="", **_kw):
        self.labels.append(text)

    def __getattr__(self, _name):
        return lambda *a, **kw: _Layout(self.labels)


def test_below_5_3_our_import_makes_our_mesh(blender, tmp_path, write_3dgs_ply):
    from gs_ibl_addon.blender.splats import object as splat_object
    from gs_ibl_addon.blender.ui.panel import GSIBL_PT_panel
    if splat_object.native_splats_supported():
        pytest.skip("this Blender has native splats: the matrix's bpy-5.3 entry checks that path")
    path = tmp_path / "s.ply"
    write_3dgs_ply(path, random_scene(20, sh_degree=1))
    assert blender.ops.gs_ibl.import_splats(filepath=str(path), native=True) == {"FINISHED"}
    obj = blender.context.active_object
    assert splat_object.is_mesh_splats(obj) and not obj.hide_render
    with pytest.raises(ValueError, match="no native Gaussian splats"):
        splat_object.create_splat_object(blender.context, random_scene(5), "N", native=True)
    labels: list[str] = []
    GSIBL_PT_panel.draw(SimpleNamespace(layout=_Layout(labels)), blender.context)
    assert "20 splats, SH 1" in labels and "s.ply" in labels
