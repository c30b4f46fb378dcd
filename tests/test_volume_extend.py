"""A light volume grown when a mesh leaves it (issue 37: "re-baked only ... where it changed"): on its own lattice,
its old nodes and bricks kept as they were, only the new nodes, the new cells' centres and their bricks rendered
(core/probe/volume_refine.py extend_volume), on lavapipe against the same probes baked alone."""
import numpy as np
import pytest

from gs_ibl_addon.core.probe import volume_rooms as rooms
from gs_ibl_addon.core.probe.volume import NORMAL_BIAS, flat_maps, probe_positions, sample, spec_spacing
from gs_ibl_addon.core.probe.volume_bake import bake_probes, far_distance
from gs_ibl_addon.core.probe.volume_refine import bake_refined, extend_volume, grown_spec
from gs_ibl_addon.core.probe.volume_region import plan_volume
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.synthetic import fibonacci_sphere

FACE = 16
BOX_A = (np.array([-0.9, -0.6, 0.6]), np.array([-0.1, 0.2, 1.4]))  # where the mesh stood at the bake
BOX_B = (np.array([0.05, 0.1, 1.2]), np.array([0.45, 0.5, 1.6]))  # where it went: under the lamp


@pytest.fixture(scope="module")
def baked():
    with SplatRenderer(rooms.lamp_room()) as r:
        spec = plan_volume([BOX_A], 0.4).spec
        prev = bake_refined(r, spec, 200, boxes=[BOX_A], face_size=FACE)
        grown = extend_volume(r, prev, [BOX_A, BOX_B], budget=400, face_size=FACE)
        full = bake_refined(r, grown.spec, 400, boxes=[BOX_A, BOX_B], face_size=FACE)  # the re-bake it spares
        yield r, prev, grown, full


def test_boxes_inside_the_volume_grow_nothing(baked):
    r, prev, _, _ = baked
    assert grown_spec(prev.spec, [BOX_A]) is None
    assert extend_volume(r, prev, [BOX_A], budget=400, face_size=FACE) is prev  # nothing to render


def test_the_grown_volume_keeps_its_lattice_and_its_old_probes(baked):
    r, prev, grown, full = baked
    assert grown is not None and all(b >= a for a, b in zip(prev.spec.shape, grown.spec.shape))
    assert grown.spec.count > prev.spec.count
    old_pos, new_pos = probe_positions(prev.spec), probe_positions(grown.spec)
    # every old node is a node of the grown grid, with its maps as they were
    d = np.linalg.norm(new_pos[:, None] - old_pos[None], axis=2)
    at = d.argmin(0)
    assert d.min(0).max() < 1e-9
    np.testing.assert_array_equal(flat_maps(grown.irradiance)[at], flat_maps(prev.irradiance))
    np.testing.assert_array_equal(flat_maps(grown.moments)[at], flat_maps(prev.moments))
    # the new nodes are what baking them alone gives (same far and near as the old volume's)
    new = np.setdiff1d(np.arange(len(new_pos)), at)
    alone = bake_probes(r, new_pos[new], far_distance(prev.spec), 0.5 * spec_spacing(prev.spec), FACE)
    np.testing.assert_allclose(flat_maps(grown.irradiance)[new], alone["irradiance"], rtol=1e-3, atol=1e-5)
    # only what changed was rendered: the new nodes, the new cells' centres and their bricks
    t = grown.timings
    assert t["kept"] == prev.spec.count and t["probes"] == len(new) + t["centres"] + t["bricks"]
    print(f"\ngrown: {t['probes']} probes rendered, {t['kept']} nodes kept; a whole re-bake: "
          f"{full.timings['probes']}")
    assert t["probes"] < full.timings["probes"]
    assert np.all(np.asarray(grown.spec.lo) <= BOX_B[0] + 1e-9) and np.all(np.asarray(grown.spec.hi) >= BOX_B[1] - 1e-9)


def test_the_old_part_lights_as_before(baked):
    """Points in the old volume's cells read the same light from the grown one: their corners and bricks kept. (Within
    the lookup's normal offset of the old faces a point now reads the new cells beyond, which the old volume clamped:
    those are left out.)"""
    _, prev, grown, _ = baked
    rng = np.random.default_rng(3)
    margin = NORMAL_BIAS * spec_spacing(prev.spec) + 1e-3
    lo, hi = BOX_A[0] + margin, BOX_A[1] - margin
    pts = lo + (hi - lo) * rng.random((200, 3))
    normals = fibonacci_sphere(200)
    np.testing.assert_allclose(sample(grown, pts, normals), sample(prev, pts, normals), rtol=1e-6, atol=1e-9)


def test_the_new_part_is_lit_by_the_lamp(baked):
    """Under the lamp the grown volume holds the lamp's light, which the old one clamped to its face missed."""
    _, prev, grown, _ = baked
    p = np.array([[0.3, 0.35, 1.45]])
    up = np.array([[0.0, 0.0, 1.0]])
    assert sample(grown, p, up).sum() > 1.5 * sample(prev, p, up).sum()
