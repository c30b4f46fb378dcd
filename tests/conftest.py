"""Fixtures shared by the Blender tests (bpy is imported only by the tests that ask for it)."""
from __future__ import annotations

import os
import shutil
import tempfile

import numpy as np
import pytest

from gs_ibl_addon.core.scene import SplatScene

# Hermetic: the Vulkan pipeline cache of every test (and of the subprocesses they start, which inherit it) goes to a
# folder of this session, never the user's ~/.cache; tests/test_pipeline_cache.py points it elsewhere per test.
_PIPELINE_CACHE_DIR = tempfile.mkdtemp(prefix="gs-ibl-test-pipeline-cache-")
os.environ["GS_IBL_CACHE_DIR"] = _PIPELINE_CACHE_DIR


def pytest_unconfigure(config) -> None:
    shutil.rmtree(_PIPELINE_CACHE_DIR, ignore_errors=True)


def _write_3dgs_ply(path, scene: SplatScene) -> None:
    """The standard 3DGS layout (raw, un-activated values), written with plyfile directly, not by the core's writer,
    so that the importer is checked against an independent file."""
    from plyfile import PlyData, PlyElement
    n, k = scene.count, scene.sh.shape[1]
    names = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(3 * (k - 1))] + \
        ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    rest = scene.sh[:, 1:].transpose(0, 2, 1).reshape(n, -1)  # channel-major
    op = np.log(scene.opacities / (1 - scene.opacities))
    cols = np.concatenate([scene.positions, scene.sh[:, 0], rest, op[:, None], np.log(scene.scales), scene.rotations], 1)
    arr = np.empty(n, [(nm, "f4") for nm in names])
    for i, nm in enumerate(names):
        arr[nm] = cols[:, i]
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(path))


@pytest.fixture
def write_3dgs_ply():
    """``write_3dgs_ply(path, scene)``: a standard 3DGS PLY written independently of the core."""
    return _write_3dgs_ply


@pytest.fixture
def blender():
    """bpy with an empty factory scene and the extension registered; unregistered afterwards."""
    bpy = pytest.importorskip("bpy")
    import gs_ibl_addon
    bpy.ops.wm.read_factory_settings(use_empty=True)
    gs_ibl_addon.register()
    yield bpy
    gs_ibl_addon.unregister()
