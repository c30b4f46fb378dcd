"""The fuzz corpus's damaged files (tests/fuzz_corpus.py) through Blender's File > Import operator (bpy module):
each is reported with the core's one-line message naming the file and leaves the .blend as it was; the new
formats (SOG zip and folder, GLB, .ksplat) import through the same operator.
"""
from __future__ import annotations

import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from fuzz_corpus import file_cases, good_scene  # noqa: E402
from gs_ibl_addon.core.formats import SplatFormatError, read_scene  # noqa: E402

KINDS = ("objects", "meshes", "images", "materials", "node_groups", "collections")


def _counts() -> dict[str, int]:
    return {k: len(getattr(bpy.data, k)) for k in KINDS + (("pointclouds",) if hasattr(bpy.data, "pointclouds") else ())}


def test_every_damaged_file_is_reported_and_nothing_is_made(blender, tmp_path):
    cases = file_cases(str(tmp_path / "files"))
    before = _counts()
    for name, path in cases:
        with pytest.raises(SplatFormatError) as core:
            read_scene(path)
        with pytest.raises(RuntimeError) as e:  # bpy.ops turns the operator's ERROR report into RuntimeError
            bpy.ops.gs_ibl.import_splats(filepath=path)
        msg = str(e.value)
        assert str(core.value) in msg and "Traceback" not in msg, (name, msg)
        assert _counts() == before, name


@pytest.mark.parametrize("fmt", ["sog", "sog folder", "glb", "ksplat"])
def test_new_formats_import(blender, tmp_path, fmt):
    from gs_ibl_addon.core.formats.gltf import write_glb
    from gs_ibl_addon.core.formats.ksplat import write_ksplat
    from gs_ibl_addon.core.formats.sog import write_sog
    scene = good_scene(500)
    if fmt.startswith("sog"):
        path = tmp_path / "s.sog"
        write_sog(path, scene)
        if fmt == "sog folder":
            import zipfile
            zipfile.ZipFile(path).extractall(tmp_path / "sogdir")
            path = tmp_path / "sogdir" / "meta.json"  # what a file browser can pick inside a SOG folder
    else:
        path = tmp_path / f"s.{fmt}"
        (write_glb if fmt == "glb" else write_ksplat)(path, scene)
    before = _counts()["objects"]
    assert bpy.ops.gs_ibl.import_splats(filepath=str(path)) == {"FINISHED"}
    assert _counts()["objects"] == before + 1
    obj = bpy.context.active_object
    assert obj["gs_ibl"]["source"] == str(path) and obj["gs_ibl"]["sh_degree"] == read_scene(path).sh_degree
    # what was imported is what the core reads (formats' own precision is tested in tests/test_formats_ecosystem.py)
    np.testing.assert_allclose(read_scene(path).positions, scene.positions, atol=1e-2)
