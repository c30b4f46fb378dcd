"""GPU splat renderer against the numpy reference, on lavapipe in CI (or whatever device GS_IBL_DEVICE picks)."""
from dataclasses import replace

import numpy as np
import pytest

from gs_ibl_addon.core.cubemap import face_directions, seam_ratio
from gs_ibl_addon.core.render.reference import render_reference
from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.renderer import SplatRenderer, render_cubemap
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc
from gs_ibl_addon.core.synthetic import random_scene

# float32 on the GPU against float64 in numpy, through exp() and up to hundreds of compositing steps
TOL = 2e-4


def one_splat(pos, scale=(0.2, 0.2, 0.2), rgb=(1.0, 0.5, 0.25), opacity=0.9) -> SplatScene:
    return SplatScene(np.array([pos], np.float32), np.array([scale], np.float32),
                      np.array([[1, 0, 0, 0]], np.float32), np.array([opacity], np.float32),
                      rgb_to_sh_dc(np.array([[rgb]], np.float32)), colour_space="linear")  # rgb is the light


def assert_matches_reference(scene, batch, tol=TOL):
    gpu = SplatRenderer(scene).render(batch)
    ref = render_reference(scene, batch)
    for v, (a, b) in enumerate(zip(gpu.images, ref)):
        err = np.abs(a - b).max()
        assert err < tol, f"view {v}: max |gpu - reference| = {err:.2e} > {tol}"
    return gpu, ref


@pytest.mark.parametrize("sh_degree", [0, 3])
def test_cubemap_matches_reference(sh_degree):
    scene = random_scene(400, seed=3, sh_degree=sh_degree, extent=2.0)
    gpu, ref = assert_matches_reference(scene, ViewBatch.cubemap([0.1, -0.2, 0.05], 24))
    # the scene is not trivially empty or saturated on any face
    cov = [img[..., 3].mean() for img in ref]
    assert min(cov) > 0.05 and max(cov) < 0.999, cov


def test_pinhole_matches_reference_non_square_and_partial_tiles():
    scene = random_scene(500, seed=4, sh_degree=3, extent=1.0)
    assert_matches_reference(scene, ViewBatch.pinhole([0.3, -4.0, 1.0], [0, 0, 0], 50.0, 50, 37))


def test_splats_straddling_and_near_the_probe():
    # big splats around the probe cross face planes: the whole-face fallback of the tile bounds must cover them
    rng = np.random.default_rng(7)
    n = 60
    pos = rng.normal(0, 0.6, (n, 3)).astype(np.float32)
    scene = SplatScene(pos, np.exp(rng.uniform(-2.5, -0.5, (n, 3))).astype(np.float32),
                       np.tile(np.array([[1, 0, 0, 0]], np.float32), (n, 1)),
                       rng.uniform(0.3, 0.95, n).astype(np.float32),
                       rgb_to_sh_dc(rng.uniform(0, 1, (n, 1, 3)).astype(np.float32)))
    assert_matches_reference(scene, ViewBatch.cubemap([0, 0, 0], 16))


def test_empty_scene_renders_holes():
    res = SplatRenderer(SplatScene.empty()).render(ViewBatch.cubemap([0, 0, 0], 16))
    assert res.instances == 0
    assert all(np.all(img == 0) for img in res.images)


def test_one_splat_appears_on_the_right_face_only():
    cube, res = render_cubemap(one_splat([3.0, 0.0, 0.0], scale=(0.6, 0.6, 0.6)), [0, 0, 0], 32)
    alpha = cube[..., 3]
    assert alpha[0].max() > 0.85  # +X face: opacity 0.9 at the centre, texel centres are half a texel off it
    assert alpha[1:].max() < 5e-3  # only the tail (exp(-6.25) x 0.9 at the 45° edge) reaches other faces
    # peak at the face centre, colour as given (premultiplied by alpha)
    j, i = np.unravel_index(np.argmax(alpha[0]), alpha[0].shape)
    assert abs(j - 15.5) <= 1 and abs(i - 15.5) <= 1
    np.testing.assert_allclose(cube[0, j, i, :3] / alpha[0, j, i], [1.0, 0.5, 0.25], atol=1e-4)


def test_splat_behind_camera_costs_nothing():
    behind = one_splat([0.0, 0.0, -3.0])
    batch = ViewBatch.pinhole([0, 0, 0], [0, 0, 1], 60, 32, 32, up=(0, 1, 0))
    res = SplatRenderer(behind).render(batch)
    assert res.instances == 0 and np.all(res.images[0] == 0)
    # and one far outside the field of view, to the side
    side = one_splat([5.0, 0.0, 0.2], scale=(0.05, 0.05, 0.05))
    assert SplatRenderer(side).render(batch).instances == 0


def test_splat_across_a_cube_edge_lands_on_both_faces():
    # centred on the +X/+Y edge direction: both faces see it, and it reads the same on both sides of the seam
    cube, res = render_cubemap(one_splat([2.0, 2.0, 0.0], scale=(0.3, 0.3, 0.3)), [0, 0, 0], 32)
    a = cube[..., 3]
    assert a[0].max() > 0.5 and a[2].max() > 0.5
    assert abs(a[0].max() - a[2].max()) < 1e-3


def test_no_seams_on_a_dense_scene():
    scene = random_scene(3000, seed=5, sh_degree=1, extent=3.0)
    cube, _ = render_cubemap(scene, [0.05, 0.02, -0.03], 48)
    # a colour step across a cube edge is no larger than the same step one texel inside a face (1.0 = no seam)
    assert seam_ratio(cube) < 1.25


def test_holes_show_as_alpha_below_one():
    # splats only in the upper hemisphere: the -Z face is a hole, +Z is covered
    rng = np.random.default_rng(2)
    d = rng.normal(size=(4000, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.3
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = len(d)
    scene = SplatScene((5 * d).astype(np.float32), np.full((n, 3), 0.35, np.float32),
                       np.tile(np.array([[1, 0, 0, 0]], np.float32), (n, 1)), np.full(n, 0.95, np.float32),
                       rgb_to_sh_dc(np.full((n, 1, 3), 0.7, np.float32)))
    cube, _ = render_cubemap(scene, [0, 0, 0], 16)
    assert cube[5, ..., 3].max() == 0.0  # -Z: nothing at all
    assert cube[4, ..., 3].min() > 0.99  # +Z: covered


def test_buffers_are_reused_when_only_the_probe_moves():
    scene = random_scene(200, seed=9, sh_degree=0, extent=1.0)
    r = SplatRenderer(scene)
    first = r.pos_op.serial
    for origin in ([0, 0, 0], [0.3, 0.1, 0.0]):
        res = r.render(ViewBatch.cubemap(origin, 16))
        ref = render_reference(scene, ViewBatch.cubemap(origin, 16))
        assert max(np.abs(a - b).max() for a, b in zip(res.images, ref)) < TOL
    assert r.pos_op.serial == first


def test_instance_overflow_is_recovered():
    scene = random_scene(300, seed=11, sh_degree=0, extent=1.0)
    r = SplatRenderer(scene)
    r._ensure_capacity(1)  # no-op: capacity only grows
    r.capacity = 8  # pretend the previous frame was tiny: the renderer must notice and re-render
    res = r.render(ViewBatch.cubemap([0, 0, 0], 16))
    assert res.instances > 8 and r.capacity >= res.instances
    ref = render_reference(scene, ViewBatch.cubemap([0, 0, 0], 16))
    assert max(np.abs(a - b).max() for a, b in zip(res.images, ref)) < TOL


def test_cube_faces_follow_the_cubemap_convention():
    # a splat placed along a face texel's direction lights that texel in the rendered cube
    dirs = face_directions(8)
    for face, j, i in [(0, 1, 6), (3, 7, 2), (5, 4, 4)]:
        d = dirs[face, j, i]
        cube, _ = render_cubemap(one_splat(4 * d, scale=(0.3, 0.3, 0.3)), [0, 0, 0], 8)
        assert np.unravel_index(np.argmax(cube[..., 3]), cube.shape[:3]) == (face, j, i)


def test_probe_dilation_is_one_size_and_keeps_a_small_splats_light():
    # Probes dilate every splat by a 1024^2 face's pixel whatever their face size (render/splat_math.py): a splat
    # smaller than that keeps its integral (alpha x solid angle) where 3DGS's dilation multiplies it, and a
    # coarse face reads the same radiance at its texel centres, so a splat both sizes resolve sends them the same
    # light.
    from gs_ibl_addon.core.cubemap import texel_solid_angles
    from gs_ibl_addon.core.render.splat_math import PROBE_DILATION_ANGLE
    assert {ViewBatch.cubemap([0, 0, 0], n).dilation for n in (16, 64, 1024)} == {PROBE_DILATION_ANGLE}
    small = one_splat([5.0, 0.0, 0.0], scale=(0.001, 0.001, 0.001), opacity=0.5)
    true_power = 0.5 * 2 * np.pi * (0.001 / 5.0) ** 2  # alpha integrated over solid angle, small-splat limit
    cube = ViewBatch.cubemap([0, 0, 0], 1024)
    kept = replace(cube, views=cube.views[:1])
    looks = replace(kept, energy_preserving=False, dilation_angle=None)  # 3DGS's: the same pixel, opacity kept
    omega = texel_solid_angles(1024)
    p_kept = (SplatRenderer(small).render(kept).images[0][..., 3] * omega).sum()
    p_look = (SplatRenderer(small).render(looks).images[0][..., 3] * omega).sum()
    assert abs(p_kept / true_power - 1) < 0.05, p_kept / true_power
    assert p_look / true_power > 10
    wide = one_splat([5.0, 0.0, 0.0], scale=(0.5, 0.5, 0.5), opacity=0.5)  # 1.6 texels at 32^2
    power = [(SplatRenderer(wide).render(ViewBatch.cubemap([0, 0, 0], n)).images[0][..., 3]
              * texel_solid_angles(n)).sum() for n in (32, 64)]
    assert power[0] == pytest.approx(power[1], rel=0.01)
    # and the reference renderer agrees with the GPU on both kinds of dilation
    for ep in (True, False):
        b = ViewBatch.cubemap([0.2, 0, 0], 16, energy_preserving=ep)
        for splat in (small, wide):
            gpu = SplatRenderer(splat).render(b).images
            ref = render_reference(splat, b)
            assert max(np.abs(a - r).max() for a, r in zip(gpu, ref)) < TOL


@pytest.mark.parametrize("max_chunks", [1, 3, 32])
def test_chunked_raster_composes_like_one_pass(monkeypatch, max_chunks):
    # few tiles: the raster splits each tile's list into chunks joined by gs_merge; any split gives the same image
    import gs_ibl_addon.core.render.renderer as renderer_module
    monkeypatch.setattr(renderer_module, "MAX_RASTER_CHUNKS", max_chunks)
    monkeypatch.setattr(renderer_module, "CPU_RASTER_TARGET_GROUPS", renderer_module.RASTER_TARGET_GROUPS)  # lavapipe too
    scene = random_scene(800, seed=12, sh_degree=1, extent=1.5)
    batch = ViewBatch.cubemap([0.05, 0.0, 0.1], 16)
    r = SplatRenderer(scene)
    assert r.render(batch) is not None and r.chunks == max_chunks
    assert_matches_reference(scene, batch)


@pytest.mark.parametrize("max_chunks", [1, 32])
def test_depth_matches_reference_and_known_distances(monkeypatch, max_chunks):
    import gs_ibl_addon.core.render.renderer as renderer_module
    monkeypatch.setattr(renderer_module, "MAX_RASTER_CHUNKS", max_chunks)
    monkeypatch.setattr(renderer_module, "CPU_RASTER_TARGET_GROUPS", renderer_module.RASTER_TARGET_GROUPS)
    scene = random_scene(400, seed=21, sh_degree=1, extent=2.0)
    batch = ViewBatch.pinhole([0.0, -6.0, 0.5], [0, 0, 0], 50, 40, 30)
    gpu = SplatRenderer(scene).render(batch, depth=True)
    images, depths = render_reference(scene, batch, with_depth=True)
    covered = images[0][..., 3] > 0.01
    assert covered.mean() > 0.2
    np.testing.assert_allclose(gpu.depths[0][covered], depths[0][covered], rtol=1e-3)
    assert np.all(gpu.depths[0][images[0][..., 3] == 0] == 0)
    # a flat nearly opaque splat facing the camera 4 units away, in front of another 9 units away: the depth is
    # their coverage-weighted mean, (0.99 * 4 + 0.01 * 0.99 * 9) / (0.99 + 0.01 * 0.99) = 4.0495
    q = np.array([[1, 0, 0, 0]] * 2, np.float32)
    two = SplatScene(np.array([[0, 4, 0], [0, 9, 0]], np.float32), np.array([[1, 0.01, 1]] * 2, np.float32), q,
                     np.array([0.99, 0.99], np.float32), rgb_to_sh_dc(np.full((2, 1, 3), 0.5, np.float32)))
    img = SplatRenderer(two).render(ViewBatch.pinhole([0, 0, 0], [0, 1, 0], 40, 32, 32), depth=True).depths[0]
    assert abs(img[16, 16] - 4.0495) < 0.01


@pytest.mark.parametrize("sh_degree", [1, 3])
def test_sh_layouts_render_the_same(monkeypatch, sh_degree):
    """The splat-major SH upload (renderer.SH_SPLAT_MAJOR) is a layout, not a rule: a cubemap and a camera view
    come out bit for bit as with the coefficient-major one."""
    scene = random_scene(700, seed=11, sh_degree=sh_degree, extent=2.0)
    cam = np.eye(4)
    cam[:3, 3] = (0.2, -0.1, 0.3)
    batches = (ViewBatch.cubemap([0.1, -0.2, 0.05], 24), ViewBatch.camera(cam, 0.6, 0.4, 70, 45))
    images = {}
    for layout in (False, True):
        monkeypatch.setattr(R, "SH_SPLAT_MAJOR", layout)
        with SplatRenderer(scene) as r:
            assert r.sh_splat_major is layout
            images[layout] = [r.render(b).images for b in batches]
    for b, (a, s) in enumerate(zip(images[False], images[True])):
        for v, (x, y) in enumerate(zip(a, s)):
            assert np.array_equal(x, y), f"batch {b} view {v}: the layouts differ by {np.abs(x - y).max():.2e}"
        assert max(float(x[..., 3].mean()) for x in a) > 0.05  # something was drawn


def test_single_view_sorts_only_its_drawn_splats(monkeypatch):
    """A camera view packs its drawn pairs before the depth sort (renderer.COMPACT_VIEWS): the same image bit for
    bit, and the same depth order of the drawn splats, as sorting every splat with the culled ones keyed last."""
    scene = random_scene(3000, seed=5, sh_degree=3, extent=2.0)
    cam = np.eye(4)
    batch = ViewBatch.camera(cam, 0.5, 0.3, 64, 40)
    out = {}
    for compact in (True, False):
        monkeypatch.setattr(R, "COMPACT_VIEWS", compact)
        with SplatRenderer(scene) as r:
            r.render(batch)
            res = r.render(batch)  # the second frame: recorded again for the budget the first one learnt
            drawn = r.drawn
            keys, order = r.read_depth_order(scene.count)
            out[compact] = (res.images[0], drawn, keys, order)
            r.render_probes(np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]]), 16)  # pair buffers grow
            assert np.array_equal(r.render(batch).images[0], res.images[0])
            r.trim()  # and are given back
            assert np.array_equal(r.render(batch).images[0], res.images[0])
    image, drawn, keys, order = out[True]
    assert np.array_equal(image, out[False][0])
    assert 0 < drawn < scene.count // 2  # most of the box is outside a 60-degree view
    full_keys, full_order = out[False][2], out[False][3]
    assert np.all(full_keys[drawn:] == 0xFFFFFFFF) and np.all(full_keys[:drawn] != 0xFFFFFFFF)
    assert np.array_equal(keys[:drawn], full_keys[:drawn]) and np.array_equal(order[:drawn], full_order[:drawn])
