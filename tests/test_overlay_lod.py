"""The overlay's motion copy (overlay_math.SplatOverlay, core/render/coarse.py) on real lavapipe: while the view
moves a big scene is drawn from a coarse merged copy, close to the full image; once still the image is exactly the
one the overlay drew before the copy existed; the switch follows ViewMotion."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.blender.viewport.overlay_math import (SplatOverlay, ViewMotion, look_at_view_matrix, overlay_view,
                                               perspective_matrix, view_key)
from gs_ibl_addon.core.render.coarse import coarse_scene
from gs_ibl_addon.core.render.lod import _grid, mean_footprint
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.scene import SplatScene
from gs_ibl_addon.core.synthetic import random_scene

W, H = 160, 120
POS, TARGET = (2.5, -3.0, 1.6), (0.0, 0.2, 0.1)
BUDGET = 3000
# Mean |RGBA| of the stretched moving image against the still one, on this 30k-splat box seen from outside: the
# copy (2.7k splats at half the moving resolution) measured 0.062, the full scene at the moving scale 0.029.
COARSE_TOL = 0.1


def scene(n: int = 30000) -> SplatScene:
    return random_scene(n, seed=5, sh_degree=1, extent=1.0)


def shuffled(s: SplatScene, seed: int = 1) -> SplatScene:
    p = np.random.default_rng(seed).permutation(s.count)
    return SplatScene(s.positions[p], s.scales[p], s.rotations[p], s.opacities[p], s.sh[p],
                      colour_space=s.colour_space)


def stretch(rgba: np.ndarray, w: int, h: int) -> np.ndarray:
    """Nearest-texel resize to (h, w): enough to compare a coarse image with a full one pixel by pixel."""
    ih, iw = rgba.shape[:2]
    return rgba[(np.arange(h) * ih) // h][:, (np.arange(w) * iw) // w].astype(np.float64)


def views():
    p = perspective_matrix(50.0, W, H)
    return [look_at_view_matrix((POS[0] + 0.05 * k, POS[1], POS[2]), TARGET) for k in range(4)], p


def test_coarse_scene_is_within_budget_and_merges_by_moments():
    s = scene(20000)
    c = coarse_scene(s, 2000)
    assert 0.5 * 2000 <= c.scene.count <= 2000 and c.merged > 0 and c.cell > 0
    assert coarse_scene(s, s.count).scene is s  # within the budget: the scene itself
    # numpy reference of the grid: the busiest cell's merged splat sits at its splats' weighted mean (weight =
    # opacity x mean footprint); a splat alone in its cell is copied as it is
    corner, cell1, bits = _grid(s)
    pos = s.positions.astype(np.float64)
    inside = np.all((pos >= corner) & (pos < corner + cell1 * 2 ** bits), 1)
    cells = np.floor((pos - corner) / c.cell).astype(np.int64)
    key = np.where(inside, (cells[:, 0] * 4096 + cells[:, 1]) * 4096 + cells[:, 2], -1 - np.arange(s.count))
    uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    members = inverse == np.argmax(counts)
    w = s.opacities[members] * mean_footprint(s.scales[members])
    want = (pos[members] * w[:, None]).sum(0) / w.sum()
    assert np.min(np.linalg.norm(c.scene.positions - want, axis=1)) < 1e-5
    alone = np.flatnonzero(counts[inverse] == 1)
    assert len(alone) > 0
    for i in alone[:20]:
        j = np.flatnonzero(np.all(c.scene.positions == s.positions[i], 1))
        assert len(j) == 1 and c.scene.opacities[j[0]] == s.opacities[i]
        np.testing.assert_array_equal(c.scene.sh[j[0]], s.sh[i])
    assert c.scene.count == int((counts == 1).sum()) + c.merged


def test_moving_image_is_coarser_but_close_and_still_image_is_exact():
    vs, p = views()
    s = shuffled(scene())  # storage order is not the grid's: the copy must not depend on it
    plain = SplatRenderer(s)
    ov = SplatOverlay(s, motion_budget=BUDGET, frame_ms=0.0, background=False)  # every render counts as slow
    still = ov.image(vs[0], p, W, H, 1.0, moving=False)
    today = plain.render(overlay_view(vs[0], p, W, H, 1.0).batch, depth=True)
    np.testing.assert_array_equal(still.rgba, today.images[0])  # bit for bit: the full scene, as before
    np.testing.assert_array_equal(still.depth, today.depths[0])
    assert not still.coarse and ov.motion is not None and ov.motion.ready()
    assert 0.5 * BUDGET <= ov.motion.coarse.scene.count <= BUDGET

    moving = ov.image(vs[0], p, W, H, 0.5, moving=True)
    assert moving.coarse and moving.scale == pytest.approx(0.25)  # MOTION_RESOLUTION of the moving scale
    full_moving = plain.render(overlay_view(vs[0], p, W, H, 0.5).batch).images[0]
    err = np.abs(stretch(moving.rgba, W, H) - still.rgba).mean()
    err_full = np.abs(stretch(full_moving, W, H) - still.rgba).mean()
    assert err < COARSE_TOL and err > err_full  # coarser than the full scene at the moving scale, but close
    assert abs(moving.rgba[..., 3].mean() - still.rgba[..., 3].mean()) < 0.05  # coverage kept by the merge
    # the same scene in another storage order gives the same copy and the same moving image
    ov2 = SplatOverlay(scene(), motion_budget=BUDGET, frame_ms=0.0, background=False)
    ov2.image(vs[0], p, W, H, 1.0)
    np.testing.assert_array_equal(ov2.image(vs[0], p, W, H, 0.5, moving=True).rgba, moving.rgba)

    again = ov.image(vs[0], p, W, H, 1.0, moving=False)  # still again: the full scene, exactly
    np.testing.assert_array_equal(again.rgba, today.images[0])
    for o in (ov, ov2):
        o.close()
    plain.close()


def test_switch_follows_view_motion():
    vs, p = views()
    s = scene()
    ov = SplatOverlay(s, motion_budget=BUDGET, frame_ms=0.0, background=False)
    m, full = ViewMotion(settle_s=0.25, moving_scale=0.25), 0.5
    drawn = []

    def draw(view, now):
        scale = m.scale("r", view_key(view, p, W, H), now, full)
        img = ov.image(view, p, W, H, scale, slot="r", moving=m.moving("r"))
        drawn.append((img.coarse, img.scale))
        return img

    first = draw(vs[0], 10.0)  # first sight: still
    assert not m.moving("r") and drawn[-1] == (False, full)
    for k, t in ((1, 10.5), (2, 10.6), (3, 10.7)):  # orbiting: the copy at half the moving scale
        draw(vs[k], t)
        assert m.moving("r") and drawn[-1] == (True, 0.125)
    assert m.refine_in(10.8) == pytest.approx(0.15)
    settled = draw(vs[3], 10.96)  # still: full detail at the Resolution setting
    assert not m.moving("r") and drawn[-1] == (False, full) and m.refine_in(10.96) is None
    plain = SplatRenderer(s)
    np.testing.assert_array_equal(settled.rgba, plain.render(overlay_view(vs[3], p, W, H, full).batch).images[0])
    assert draw(vs[0], 12.0).coarse  # moved back: coarse again, then still: full detail again
    want = plain.render(overlay_view(vs[0], p, W, H, full).batch).images[0]
    np.testing.assert_array_equal(draw(vs[0], 12.5).rgba, want)

    # A Resolution already below the moving scale: the scale stays, the detail still drops while moving, and the
    # region is refined once still (the copy was drawn at full scale).
    m2 = ViewMotion(settle_s=0.25, moving_scale=0.25)
    m2.scale("q", view_key(vs[0], p, W, H), 20.0, 0.2)
    assert m2.scale("q", view_key(vs[1], p, W, H), 20.1, 0.2) == 0.2 and m2.moving("q")
    assert ov.image(vs[1], p, W, H, 0.2, slot="q", moving=m2.moving("q")).coarse
    assert m2.refine_in(20.1) == pytest.approx(0.25)
    assert m2.scale("q", view_key(vs[1], p, W, H), 20.4, 0.2) == 0.2 and not m2.moving("q")
    assert m2.refine_in(20.4) is None
    assert first.coarse is False
    ov.close()
    plain.close()


def test_scenes_that_keep_up_or_fit_the_budget_make_no_copy():
    vs, p = views()
    s = scene(5000)
    fast = SplatOverlay(s, motion_budget=BUDGET, frame_ms=1e9, background=False)  # every render fits the frame
    fast.image(vs[0], p, W, H, 1.0)
    assert fast.motion is None and not fast.image(vs[1], p, W, H, 0.5, moving=True).coarse
    small = SplatOverlay(renderer=fast.renderer, motion_scene=s, motion_budget=s.count, frame_ms=0.0)
    small.image(vs[0], p, W, H, 1.0)
    assert small.motion is None and not small.image(vs[1], p, W, H, 0.5, moving=True).coarse
    no_source = SplatOverlay(renderer=fast.renderer, motion_budget=10, frame_ms=0.0)  # the handler gave no scene
    no_source.image(vs[0], p, W, H, 1.0)
    assert no_source.motion is None
    small.close()
    no_source.close()
    fast.close()


def test_copy_builds_on_a_worker_thread_and_moving_frames_wait_for_nothing():
    vs, p = views()
    s = scene()
    ov = SplatOverlay(s, motion_budget=BUDGET, frame_ms=0.0)  # background build
    ov.image(vs[0], p, W, H, 1.0)
    assert ov.motion is not None
    # until the copy is ready a moving frame is the full scene at the moving scale, as before the copy
    img = ov.image(vs[1], p, W, H, 0.5, moving=True)
    assert img.coarse == ov.motion.ready() or not img.coarse
    assert ov.motion.wait(60.0) and ov.motion.error is None and ov.motion.build_s > 0
    assert ov.image(vs[2], p, W, H, 0.5, moving=True).coarse
    ov.close()
