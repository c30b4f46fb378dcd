"""The level of detail (render/lod.py): the merge keeps each cluster's weight, mean, covariance and colour; the cut
draws every splat through exactly one node; the GPU's cut (gs_preprocess + gs_lod_compact) is the numpy one; the
storage order does not matter; lod_k = 0 is the renderer without a level of detail."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.render.lod import (NO_PARENT, _ein, build_lod, cut, matrix_to_quat_batch, mean_footprint,
                                          opacity_for_weight)
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene, quat_to_matrix


def _subset(s: SplatScene, m: np.ndarray) -> SplatScene:
    return SplatScene(s.positions[m], s.scales[m], s.rotations[m], s.opacities[m], s.sh[m], colour_space=s.colour_space)


def _shuffled(s: SplatScene, seed: int) -> SplatScene:
    return _subset(s, np.random.default_rng(seed).permutation(s.count))


@pytest.fixture(scope="module")
def scene() -> SplatScene:
    return _shuffled(synthetic.sample_environment(), 3)


@pytest.fixture(scope="module")
def tree(scene):
    return build_lod(scene)


def _leaf_cells(tree, level: int) -> np.ndarray:
    """Each splat's cell key at ``level`` (>= 1)."""
    c = tree.cell[:tree.leaves].astype(np.int64) >> (level - 1)
    return (c[:, 0] << 32) | (c[:, 1] << 16) | c[:, 2]


def _node_keys(tree, idx: np.ndarray) -> np.ndarray:
    c = tree.cell[idx].astype(np.int64)
    return (c[:, 0] << 32) | (c[:, 1] << 16) | c[:, 2]


def _coverage(tree, drawn: np.ndarray) -> np.ndarray:
    """How many drawn nodes stand for each splat (itself or a merged node whose cell holds it)."""
    inside = tree.parent_level[:tree.leaves] != NO_PARENT
    cover = drawn[:tree.leaves].astype(int)
    for level in range(1, tree.levels + 1):
        nodes = np.flatnonzero(drawn & (tree.level == level))
        if len(nodes):
            cover += np.isin(_leaf_cells(tree, level), _node_keys(tree, nodes)) & inside
    return cover


def test_cut_draws_every_splat_exactly_once(tree, scene):
    rng = np.random.default_rng(0)
    for _ in range(6):
        probe = rng.uniform([-3, -2.5, 0], [3, 2.5, 3])
        for tau in (0.0, 0.02, 0.1, 0.5, 3.0):
            drawn = cut(tree, probe, tau)
            assert np.all(_coverage(tree, drawn) == 1), (probe, tau)
    assert cut(tree, [0, 0, 1], 0.0).sum() == scene.count  # tau 0: the splats themselves
    assert cut(tree, [0, 0, 1], 0.2).sum() < scene.count


def test_merged_nodes_keep_weight_mean_covariance_colour(tree, scene):
    """Level-1 nodes against their splats, recomputed here plainly (relative 1e-5; float32 storage)."""
    keys = _leaf_cells(tree, 1)
    inside = tree.parent_level[:tree.leaves] != NO_PARENT
    nodes = np.flatnonzero(tree.level == 1)[:40]
    rot_n = quat_to_matrix(tree.scene.rotations[nodes])
    for j, node in enumerate(nodes):
        m = inside & (keys == _node_keys(tree, np.array([node]))[0])
        assert m.sum() >= 2
        w = scene.opacities[m].astype(np.float64) * mean_footprint(scene.scales[m])
        mu = np.average(scene.positions[m].astype(np.float64), axis=0, weights=w)
        r = quat_to_matrix(scene.rotations[m])
        cov = np.einsum("nij,nj,nkj->nik", r, scene.scales[m].astype(np.float64) ** 2, r)
        d = scene.positions[m] - mu
        second = np.average(cov + np.einsum("ni,nj->nij", d, d), axis=0, weights=w)
        got = rot_n[j] @ np.diag(tree.scene.scales[node].astype(np.float64) ** 2) @ rot_n[j].T
        scale = np.abs(second).max()
        assert np.allclose(tree.scene.positions[node], mu, atol=1e-5 * (1 + np.abs(mu).max()))
        assert np.allclose(got, second, atol=2e-5 * scale + 1e-12)
        assert np.allclose(tree.scene.sh[node], np.average(scene.sh[m].astype(np.float64), axis=0, weights=w),
                           atol=1e-5)
        area = mean_footprint(tree.scene.scales[node:node + 1])
        assert tree.scene.opacities[node] == pytest.approx(opacity_for_weight(np.array([w.sum()]), area)[0], rel=1e-5)


def test_srgb_scenes_merge_their_light():
    """An sRGB capture's merged colour is the weighted mean of the light its splats stand for (decoded, averaged,
    encoded), not of the encoded values, which darkened clusters of mixed brightness (the guitar: -23%)."""
    from gs_ibl_addon.core.colour import srgb_to_linear
    from gs_ibl_addon.core.scene import SH_C0
    base = synthetic.sample_environment()
    rng = np.random.default_rng(4)
    sh = base.sh.copy()
    sh[:, 0] = (rng.choice([0.05, 0.95], (base.count, 3)) - 0.5) / SH_C0  # dark and bright neighbours
    s = SplatScene(base.positions, base.scales, base.rotations, base.opacities, sh, colour_space="srgb")
    tree = build_lod(s)
    keys = _leaf_cells(tree, 1)
    inside = tree.parent_level[:tree.leaves] != NO_PARENT
    for node in np.flatnonzero(tree.level == 1)[:40]:
        m = inside & (keys == _node_keys(tree, np.array([node]))[0])
        w = s.opacities[m].astype(np.float64) * mean_footprint(s.scales[m])
        light = np.average(srgb_to_linear(SH_C0 * s.sh[m, 0].astype(np.float64) + 0.5), axis=0, weights=w)
        got = srgb_to_linear(SH_C0 * tree.scene.sh[node, 0].astype(np.float64) + 0.5)
        assert np.allclose(got, light, rtol=1e-4, atol=1e-6)


def test_srgb_light_conversion_round_trips():
    # higher bands go through the curve's slope at the DC colour; a single splat's node would come back unchanged
    from gs_ibl_addon.core.render.lod import _sh_from_linear, _sh_to_linear
    sh = np.random.default_rng(2).normal(0, 0.3, (500, 16, 3))
    sh[:, 0] = np.random.default_rng(3).uniform(-1.5, 2.5, (500, 3))  # encoded colour ~0.08 .. 1.2
    assert np.allclose(_sh_from_linear(_sh_to_linear(sh)), sh, rtol=1e-9, atol=1e-9)


def test_opacity_model():
    t = np.array([1e-3, 0.3, 1.0, 4.0, 11.99, 12.01, 60.0])
    x = np.linspace(1e-9, 1, 400001)[:, None] * t[None, :]
    trapezoid = getattr(np, "trapezoid", None) or np.trapz  # numpy 2 renamed it (and 2.4 dropped the old name)
    numeric = trapezoid((1 - np.exp(-x)) / x, x, axis=0)
    assert np.allclose(_ein(t), numeric, rtol=1e-4)
    # a thin cluster keeps its weight; a Gaussian's own weight gives back its opacity
    area = np.array([2.0])
    assert opacity_for_weight(np.array([1e-3]) * area, area)[0] == pytest.approx(1e-3, rel=1e-3)
    q = np.random.default_rng(1).standard_normal((50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    assert np.allclose(quat_to_matrix(matrix_to_quat_batch(quat_to_matrix(q))), quat_to_matrix(q), atol=1e-9)


def test_storage_order_does_not_matter(scene, tree):
    other = build_lod(_shuffled(scene, 11))
    assert other.counts_by_level() == tree.counts_by_level()
    for level in range(1, tree.levels + 1):
        a = np.sort(tree.scene.positions[tree.level == level], axis=0)
        b = np.sort(other.scene.positions[other.level == level], axis=0)
        assert np.allclose(a, b, atol=1e-5)


def test_gpu_cut_is_the_reference_cut(tree, scene):
    """The GPU draws what cut() picks: its image equals a renderer given just those nodes, in storage order."""
    pos = np.array([0.4, -0.3, 1.1])
    batch = ViewBatch.cubemap(pos, 32)
    with SplatRenderer(scene, lod=tree) as r:
        for k in (1.0, 3.0):
            drawn = cut(tree, pos, k * batch.pixel_angle)
            assert 0 < drawn.sum() < scene.count
            got = np.stack(r.render(batch, lod_k=k).images)
            with SplatRenderer(_subset(tree.scene, drawn)) as ref:
                want = np.stack(ref.render(batch).images)
            assert np.abs(got - want).max() < 1e-5, k
            assert r.drawn <= drawn.sum()


def test_lod_k_zero_is_full_detail_and_growth(scene, tree):
    """k = 0 draws every splat, exactly as without a level of detail, also when the cut outgrows its first sizes."""
    batch = ViewBatch.cubemap([0.0, 0.0, 1.0], 32)
    with SplatRenderer(scene) as plain, SplatRenderer(scene, lod=tree) as r:
        r._grow_cut(1024)  # smaller than the cut: the first render must grow it and draw again
        want = np.stack(plain.render(batch).images)
        got = np.stack(r.render(batch).images)
        assert np.array_equal(got, want)
        assert r.cut_capacity >= r.drawn > 1024
        with pytest.raises(ValueError, match="level of detail"):
            plain.render(batch, lod_k=1.0)
        with pytest.raises(ValueError, match="lod_k"):
            r.render(batch, lod_k=-1.0)


def test_bake_settings(scene):
    from gs_ibl_addon.core.bake import BadSetting, ProbeSettings, bake_probe, check_settings, relative_rms
    for bad, name in ((dict(lod="fast"), "lod"), (dict(lod="auto", lod_k=0), "lod_k"), (dict(lod_k=True), "lod_k")):
        with pytest.raises(BadSetting) as e:
            check_settings(ProbeSettings(**bad))
        assert e.value.option == name
    full = bake_probe(scene, [0.0, 0.0, 1.0], ProbeSettings(face_size=32))
    lod = bake_probe(scene, [0.0, 0.0, 1.0], ProbeSettings(face_size=32, lod="auto", lod_k=1.0))
    assert lod.settings["lod"] == "auto" and full.settings["lod"] == "off"
    # docs/benchmarks.md: 0.89% on this scene at 32^2, k = 1 (the reason the default is off)
    assert 0 < relative_rms(lod.irradiance, full.irradiance) < 0.02
