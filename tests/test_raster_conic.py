"""The conic pre-test (gs_raster_conic, faces up to CONIC_MAX_FACE) changes which pairs a pixel tests along its
ray, never the result: it only skips pairs the ray test would reject, so both kernels give the same bits."""
import os

import numpy as np
import pytest

from gs_ibl_addon.core.formats import read_scene
from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.synthetic import concat, random_scene
from gs_ibl_addon.core.vk import get_context


GUITAR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "guitar.compressed.ply")


def _scene():
    # splats of every size against the faces' pixels: big ones around the probe (whole faces, straddling the
    # faces' planes), small far ones (below a pixel at 256²: the unexpanded quadric's cancellation), stored shuffled
    near = random_scene(300, seed=3, sh_degree=1, extent=0.6)
    far = random_scene(4000, seed=4, sh_degree=1, extent=1.0)
    far.positions = far.positions * 40.0
    far.scales = far.scales * 0.2
    scene = concat([near, far])
    order = np.random.default_rng(5).permutation(scene.count)
    return scene.subset(order)


def _both(monkeypatch, scene, batch, read):
    out = []
    # the ray test alone, then the conic first; a renderer each (it keeps its programs). The plain kernel's plane
    # forms (test_raster_plane.py) are off: they give the ray test's m to rounding, not its bits
    monkeypatch.setattr(R, "PLANE_FORMS", False)
    for limit in (0, 1 << 20):
        monkeypatch.setattr(R, "CONIC_MIN_FACE", 1)
        monkeypatch.setattr(R, "CONIC_MAX_FACE", limit)
        out.append(np.asarray(read(R.SplatRenderer(scene).render(batch))))
    return out


@pytest.mark.parametrize("face", [16, 64, 256])
def test_both_rasters_give_the_same_bits(monkeypatch, face):
    plain, conic = _both(monkeypatch, _scene(), ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), face),
                         lambda res: res.frame.read_cube())
    assert np.array_equal(plain, conic)
    assert plain[..., 3].mean() > 0.1  # the scene covers the faces: the check is not of empty images


def test_both_rasters_on_a_real_capture(monkeypatch):
    # the guitar from outside, thin real splats 58k deep in one tile: a bitmask form of the conic test got one
    # tile of this wrong on lavapipe while the cube faces above passed. It was lavapipe's loop limit (the conic
    # kernel steps its loops about twice a pair): on a CPU device the conic raster now takes that tile in two
    # chunks (renderer.LOOP_PAIRS), each ending its pixels at T < T_MIN on its own, so the two agree to T_MIN there
    scene = read_scene(GUITAR)
    lo, hi = scene.bounds()
    centre = (lo + hi) / 2
    batch = ViewBatch.pinhole(centre + np.array([1.2 * np.linalg.norm(hi - lo), 0, 0]), centre, 40, 40, 64,
                              up=(0, -1, 0))
    plain, conic = _both(monkeypatch, scene, batch, lambda res: res.images[0])
    if get_context().is_cpu:
        assert np.abs(plain - conic).max() < 2e-4  # T_MIN (1e-4) and the merge's rounding
    else:
        assert np.array_equal(plain, conic)
    assert plain[..., 3].mean() > 0.1


def test_which_faces_use_the_conic_kernel():
    def conic(face):
        return R.raster_conic(ViewBatch.cubemap(np.zeros(3), face))
    assert conic(R.CONIC_MIN_FACE) and conic(R.CONIC_MAX_FACE)
    assert not conic(R.CONIC_MIN_FACE - 1) and not conic(R.CONIC_MAX_FACE + 1)
