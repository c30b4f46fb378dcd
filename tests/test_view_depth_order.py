"""The depth order of a batch of one view (camera frames, the viewport) is 3DGS's: depth along the view axis,
z = forward . mu (shaders/gs_preprocess.comp sort_depth, splat_math.sort_depths); cube-face probes keep the distance
from the origin, one order for their six faces. Two big overlapping splats whose radial and view-depth orders
differ: the camera frame draws the nearer-in-z one in front, on the GPU as in the numpy twin, and a probe sorts
them by distance."""
import numpy as np

from gs_ibl_addon.core.render.reference import _composite, render_reference
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.splat_math import SORT_DEPTH_MIN, depth_keys, prepare, sort_depths
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc

# Blender's camera convention (looks down its -Z): at the origin, looking along world +Y with +Z up
CAM = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
W, H = 64, 48
TOL = 2e-4  # tests/test_renderer.py's


def _pair() -> SplatScene:
    """A (red) on the axis 3 m away; B (green) off to the side, 3.2 m away but only 2.5 m along the view axis."""
    f32 = np.float32
    pos = np.array([[0.0, 3.0, 0.0], [2.0, 2.5, 0.0]], f32)
    sh = rgb_to_sh_dc(np.array([[0.9, 0.05, 0.05], [0.05, 0.9, 0.05]], f32))[:, None, :]
    return SplatScene(pos, np.full((2, 3), 0.7, f32), np.tile(np.array([1, 0, 0, 0], f32), (2, 1)),
                      np.array([0.95, 0.95], f32), sh.astype(f32), colour_space="linear")


def test_one_view_sorts_by_view_depth_and_probes_by_distance():
    scene = _pair()
    batch = ViewBatch.camera(CAM, 1.0, 0.75, W, H)
    fwd = batch.views[0].forward
    np.testing.assert_allclose(fwd, [0, 1, 0], atol=1e-12)
    z, r = sort_depths(scene, np.zeros(3), fwd), sort_depths(scene, np.zeros(3))
    assert z[1] < z[0] and r[1] > r[0]  # the orders differ
    assert list(np.argsort(depth_keys(scene, np.zeros(3), fwd), kind="stable")) == [1, 0]
    assert list(np.argsort(depth_keys(scene, np.zeros(3)), kind="stable")) == [0, 1]
    # a splat centred behind the camera plane sorts first (its depth is clamped to a tiny positive value)
    behind = sort_depths(scene, np.array([0, 4.0, 0]), fwd)
    np.testing.assert_array_equal(behind, SORT_DEPTH_MIN)
    with SplatRenderer(scene) as r:
        img = r.render(batch).images[0]
        keys, order = r.read_depth_order(2)
        assert list(order) == [1, 0]  # B, nearer along the view axis, first
        np.testing.assert_array_equal(keys, depth_keys(scene, np.zeros(3), fwd)[order] >> np.uint32(8))
        r.render(ViewBatch.cubemap((0, 0, 0), 16))
        _, order = r.read_depth_order(2)
        assert list(order) == [0, 1]  # a probe: A, nearer the origin, first, for all six faces
    twin = render_reference(scene, batch)[0]
    np.testing.assert_allclose(img, twin, atol=TOL)
    # the frame is 3DGS's order (B over A), not the radial one (A over B), where both splats cover a pixel
    p = prepare(scene, batch.origin, batch.dilation)
    dirs = batch.views[0].pixel_directions().reshape(-1, 3)
    (zc, zt, _), = _composite(p, np.array([1, 0]), dirs, 64)
    (rc, rt, _), = _composite(p, np.array([0, 1]), dirs, 64)
    z_img = np.concatenate([zc, 1 - zt[:, None]], 1).reshape(H, W, 4)
    r_img = np.concatenate([rc, 1 - rt[:, None]], 1).reshape(H, W, 4)
    np.testing.assert_allclose(img, z_img, atol=TOL)
    both = (img[..., 0] > 0.05) & (img[..., 1] > 0.05)
    assert both.sum() > 20, "the splats overlap in the image"
    assert np.abs(img - r_img)[both].max() > 0.05  # the radial order would look different there
    # green B in front: greener and less red than A in front, wherever both cover a pixel
    assert np.all((img - r_img)[both][:, 1] > -TOL) and np.all((img - r_img)[both][:, 0] < TOL)


def test_the_order_is_the_batch_s_field():
    """ViewBatch.sort says the order (vk/constants.py, gs_preprocess's sort_order), whatever the batch's views:
    a face taken out of a cube keeps the radial order, and a camera view asked to sort radially does, on the GPU as in
    the numpy twin."""
    from dataclasses import replace

    import pytest

    from gs_ibl_addon.core.vk.constants import SORT_RADIAL, SORT_VIEW_DEPTH
    cube = ViewBatch.cubemap((0, 0, 0), 16)
    assert cube.sort == SORT_RADIAL and ViewBatch.cubemaps(np.zeros((2, 3)), 16).sort == SORT_RADIAL
    assert replace(cube, views=cube.views[2:3]).sort == SORT_RADIAL  # one face rendered alone (a big bake)
    camera = ViewBatch.camera(CAM, 1.0, 0.75, W, H)
    assert camera.sort == SORT_VIEW_DEPTH and ViewBatch.pinhole((0, 0, 0), (0, 1, 0), 60, W, H).sort == SORT_VIEW_DEPTH
    # a batch built field by field (the viewport's): view depth for one 3DGS-look view, as before the field
    assert ViewBatch(camera.origin, camera.views, camera.pixel_angle).sort == SORT_VIEW_DEPTH
    with pytest.raises(ValueError, match="one view"):
        replace(cube, sort=SORT_VIEW_DEPTH)
    radial = replace(camera, sort=SORT_RADIAL)
    scene = _pair()
    with SplatRenderer(scene) as r:
        img = r.render(radial).images[0]
        _, order = r.read_depth_order(2)
        assert list(order) == [0, 1]  # A, nearer the origin, first
    np.testing.assert_allclose(img, render_reference(scene, radial)[0], atol=TOL)
