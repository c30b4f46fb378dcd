"""The plain raster's plane forms (gs_raster.glsl plane_form, splat_math.plane_form): the ray test's m of a pair,
rewritten exactly as quadratic forms in the view's image plane about the splat's centre. Checked in numpy against
the ray test's m (float64: the same function), and on the GPU against the same renderer without the forms and
against the numpy reference (which has only the ray test)."""
import numpy as np
import pytest

from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.reference import render_reference
from gs_ibl_addon.core.render.splat_math import plane_form, plane_form_m, prepare, ray_mahalanobis
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene
from gs_ibl_addon.core.synthetic import concat, random_scene

TOL = 2e-4  # tests/test_renderer.py's: float32 on the GPU against float64 in numpy


def _far_scene(n: int = 3000, seed: int = 2) -> SplatScene:
    """Splats 2-50 m away in every direction, from far below a 1024² pixel to a few degrees, anisotropic (some
    needles and disks), opacities of trained scenes; stored shuffled."""
    rng = np.random.default_rng(seed)
    scene = random_scene(n, seed=seed, sh_degree=1, extent=1.0)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    scene.positions = (d * rng.uniform(2, 50, n)[:, None]).astype(np.float32)
    scene.scales = (scene.scales * rng.uniform(0.0005, 0.3, (n, 1))).astype(np.float32)
    return scene.subset(rng.permutation(n))


def _near_scene() -> SplatScene:
    """Big splats around the origin (whole faces, straddling the faces' planes), as in test_raster_conic."""
    near = random_scene(100, seed=3, sh_degree=1, extent=0.8)
    near.scales = (near.scales * 0.5).astype(np.float32)
    return near


def test_plane_form_is_the_ray_test():
    scene = concat([_near_scene(), _far_scene(1500)])
    batch = ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 64)
    p = prepare(scene, batch.origin, batch.dilation, energy_preserving=True)
    rng = np.random.default_rng(0)
    held_total = 0
    for v in batch.views:
        form = plane_form(p, slice(None), v.forward, v.right, v.down)
        held = np.where(form.held)[0]
        held_total += len(held)
        # the whole face and the footprint's surroundings: the identity holds for every ray, not near the centre only
        s = np.concatenate([rng.uniform(-1, 1, 200), np.repeat(form.s0[held], 20) + rng.normal(0, 0.01, 20 * len(held))])
        t = np.concatenate([rng.uniform(-1, 1, 200), np.repeat(form.t0[held], 20) + rng.normal(0, 0.01, 20 * len(held))])
        m, along, ahead = ray_mahalanobis(p, held, v.forward + s[:, None] * v.right + t[:, None] * v.down)
        sub = type(form)(*[getattr(form, k)[held] for k in form.__dataclass_fields__])
        m_f, along_f, ahead_f = plane_form_m(sub, s, t)
        assert np.array_equal(ahead, ahead_f)
        assert np.allclose(m_f[ahead], m[ahead], rtol=1e-6, atol=1e-9)
        assert np.allclose(along_f[ahead], along[ahead], rtol=1e-6)
    assert held_total > 0.3 * 6 * scene.count  # each splat is well in front of two faces or so


def test_plane_form_held_only_well_in_front():
    # 10 m down +X: a small blob, a big one, an undilated needle seen side-on (q ill-conditioned), and the small
    # blob again 80 degrees off the face's axis and behind it
    far = [10, 0, 0]
    scales = [[0.004] * 3, [1.5] * 3, [1e-7, 1e-7, 0.5], [0.004] * 3, [0.004] * 3]
    n = len(scales)
    scene = SplatScene(np.array([far, far, far, [1.7, 9.8, 0], [-10, 0, 0]], np.float32),
                       np.array(scales, np.float32), np.array([[1, 0, 0, 0]] * n, np.float32),
                       np.full(n, 0.9, np.float32), np.full((n, 1, 3), 0.5, np.float32), colour_space="linear")
    v = ViewBatch.cubemap(np.zeros(3), 64).views[0]
    held = plane_form(prepare(scene, np.zeros(3), 0.0), slice(None), v.forward, v.right, v.down).held
    assert held.tolist() == [True, True, False, False, False]


def _render(monkeypatch, scene, batch, forms, depth=False):
    monkeypatch.setattr(R, "PLANE_FORMS", forms)
    res = R.SplatRenderer(scene).render(batch, depth=depth)
    return res.images, (res.depths if depth else None)


def _wall(n: int = 4000, seed: int = 9) -> SplatScene:
    """Layers of small splats 18-22 m down +X across a 1.6 m square, a few big ones in front; shuffled."""
    rng = np.random.default_rng(seed)
    wall = random_scene(n, seed=seed, sh_degree=1, extent=1.0)
    wall.positions = np.stack([rng.uniform(18, 22, n), rng.uniform(-0.8, 0.8, n), rng.uniform(-0.8, 0.8, n)],
                              1).astype(np.float32)
    wall.scales = (rng.uniform(0.002, 0.03, (n, 1)) * rng.uniform(0.3, 1.0, (n, 3))).astype(np.float32)
    wall.opacities = rng.uniform(0.3, 0.95, n).astype(np.float32)
    front = random_scene(12, seed=seed + 1, sh_degree=1, extent=0.3)
    front.positions = (front.positions + np.array([8, 0, 0], np.float32)).astype(np.float32)
    scene = concat([wall, front])
    return scene.subset(rng.permutation(scene.count))


def _mixed() -> SplatScene:
    scene = concat([_near_scene(), _far_scene(2500, seed=4)])
    return scene.subset(np.random.default_rng(6).permutation(scene.count))


CASES = {
    # splats of a pixel or two, many deep: the forms' pixels dominate the image
    "wall": (_wall, lambda: ViewBatch.pinhole(np.zeros(3), np.array([20.0, 0, 0]), 4.5, 48, 40)),
    # near big splats over far small ones, on 16² and 32² cube faces: both ways in one tile, in depth order
    "cube16": (_mixed, lambda: ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 16)),
    "cube32": (_mixed, lambda: ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 32)),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_plane_forms_on_gpu_against_the_ray_test_and_numpy(monkeypatch, case):
    make_scene, make_batch = CASES[case]
    scene, batch = make_scene(), make_batch()
    assert not R.raster_conic(batch)
    ray, _ = _render(monkeypatch, scene, batch, False)
    forms, _ = _render(monkeypatch, scene, batch, True)
    ref = render_reference(scene, batch)
    diff = max(np.abs(a - b).max() for a, b in zip(forms, ray))
    assert 0 < diff < 5e-5  # the forms are taken on the GPU, and differ from the ray test by rounding only
    assert max(np.abs(a - b).max() for a, b in zip(forms, ref)) < TOL
    assert np.mean([img[..., 3].mean() for img in ref]) > 0.005  # not empty (the far splats are faint at 16²)


def test_plane_forms_depth(monkeypatch):
    scene, batch = _wall(), CASES["wall"][1]()
    images, depths = _render(monkeypatch, scene, batch, True, depth=True)
    ref_images, ref_depths = render_reference(scene, batch, with_depth=True)
    covered = ref_images[0][..., 3] > 0.01
    assert covered.mean() > 0.5
    np.testing.assert_allclose(depths[0][covered], ref_depths[0][covered], rtol=1e-4)
    assert np.abs(images[0] - ref_images[0]).max() < TOL
