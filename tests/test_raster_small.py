"""The plain raster's small-splat form (gs_raster.glsl small_form, splat_math.small_form): a pair whose footprint's
image-plane expansion gives its alpha to within renderer.SMALL_SPLAT_TOL is rastered from it instead of the ray
test. The bound is checked in numpy against the ray test's m, and the GPU's images with the form against the same
renderer without it and against the numpy reference (which has only the ray test)."""
import numpy as np
import pytest

from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.reference import render_reference
from gs_ibl_addon.core.render.splat_math import prepare, ray_mahalanobis, small_form, small_form_m
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


def _one(form, i):
    return type(form)(*[getattr(form, k)[i:i + 1] for k in form.__dataclass_fields__])


def test_small_form_alpha_within_its_bound():
    scene = _far_scene()
    batch = ViewBatch.cubemap(np.zeros(3), 64)
    p = prepare(scene, batch.origin, batch.dilation, energy_preserving=True)
    rng = np.random.default_rng(0)
    checked = flips = inside = 0
    for v in batch.views:
        form = small_form(p, slice(None), v.forward, v.right, v.down)
        held = np.where(form.error < 1e-3)[0]
        assert len(held) > 100  # most of these splats are small
        for i in held[:60]:
            # pixels over the footprint and well beyond it (a 16² face's tile holds points far out in sigmas)
            reach = 6 * np.sqrt(p.cutoff[i] / min(form.mss[i], form.mtt[i]))
            s = form.s0[i] + rng.uniform(-reach, reach, 3000)
            t = form.t0[i] + rng.uniform(-reach, reach, 3000)
            m, along, ahead = ray_mahalanobis(p, np.array([i]), v.forward + s[:, None] * v.right + t[:, None] * v.down)
            m_f, along_f = small_form_m(_one(form, i), s, t)
            hit, hit_f = (m[0] <= p.cutoff[i]) & ahead[0], m_f[0] <= p.cutoff[i]
            both = hit & hit_f
            alpha, alpha_f = p.opacity[i] * np.exp(-0.5 * m[0]), p.opacity[i] * np.exp(-0.5 * m_f[0])
            assert np.abs(alpha - alpha_f)[both].max(initial=0) <= form.error[i] * 1.0001 + 1e-12
            assert np.abs(along_f[0] / along[0] - 1)[both].max(initial=0) < 1e-3
            edge = (m_f[0] >= form.band[i, 0]) & (m_f[0] <= form.band[i, 1])  # the ray test decides there
            flips += np.sum((hit != hit_f) & ~edge)
            inside += hit.sum()
            checked += 1
    assert checked == 360 and inside > 1e4 and flips == 0


def test_small_form_takes_small_splats_only():
    # 10 m down +X: a 1024² pixel's blob, an undilated needle 5 cm long (a line of a footprint, but a short one:
    # the expansion holds), half a metre's blob, and the small blob again off the face's axis by 80 degrees (not
    # well in front of the view); undilated, 2 m needles: across the view (flat in depth, so the image-plane form
    # is exact) and tilted 45 degrees in depth (perspective: it is not)
    far = [10, 0, 0]
    v = ViewBatch.cubemap(np.zeros(3), 64).views[0]

    def error(scales, pos, dilation=2.0 / 1024, rot=(1, 0, 0, 0)):
        n = len(scales)
        scene = SplatScene(np.array(pos, np.float32), np.array(scales, np.float32),
                           np.array([rot] * n, np.float32), np.full(n, 0.9, np.float32),
                           np.full((n, 1, 3), 0.5, np.float32), colour_space="linear")
        p = prepare(scene, np.zeros(3), dilation, energy_preserving=dilation > 0)
        return small_form(p, slice(None), v.forward, v.right, v.down).error

    err = error([[0.004] * 3, [1e-7, 1e-7, 0.05], [0.5] * 3, [0.004] * 3], [far, far, far, [1.7, 9.8, 0]])
    assert err[0] < 1e-5 and err[1] < 1e-5 and err[2] > 1e-3 and np.isinf(err[3])
    assert error([[1e-7, 1e-7, 2.0]], [far], 0.0)[0] < 1e-12
    assert error([[1e-7, 1e-7, 2.0]], [far], 0.0, (np.cos(np.pi / 8), 0, np.sin(np.pi / 8), 0))[0] > 1e-3


FORM_TOL = R.SMALL_SPLAT_TOL  # as the renderer ships it (tests set the module's value)


def _render(monkeypatch, scene, batch, tol, depth=False):
    monkeypatch.setattr(R, "SMALL_SPLAT_TOL", tol)
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
    near = random_scene(100, seed=3, sh_degree=1, extent=0.8)
    near.scales = (near.scales * 0.5).astype(np.float32)
    scene = concat([near, _far_scene(2500, seed=4)])
    return scene.subset(np.random.default_rng(6).permutation(scene.count))


CASES = {
    # splats of a pixel or two, many deep: the form's pixels dominate the image
    "wall": (_wall, lambda: ViewBatch.pinhole(np.zeros(3), np.array([20.0, 0, 0]), 4.5, 48, 40)),
    # near big splats over far small ones, on 32² cube faces: both paths in one tile, in depth order
    "cube": (_mixed, lambda: ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 32)),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_small_form_on_gpu_against_the_ray_test_and_numpy(monkeypatch, case):
    make_scene, make_batch = CASES[case]
    scene, batch = make_scene(), make_batch()
    assert not R.raster_conic(batch)
    p = prepare(scene, batch.origin, batch.dilation, energy_preserving=batch.energy_preserving)
    share = np.mean([np.mean(small_form(p, slice(None), v.forward, v.right, v.down).error <= FORM_TOL)
                     for v in batch.views])
    assert share > 0.3  # the form is really taken
    ray, _ = _render(monkeypatch, scene, batch, 0.0)
    fast, _ = _render(monkeypatch, scene, batch, FORM_TOL)
    ref = render_reference(scene, batch)
    diff = max(np.abs(a - b).max() for a, b in zip(fast, ray))
    assert 0 < diff < 1e-4  # the form is taken on the GPU too, and within its tolerance
    assert max(np.abs(a - b).max() for a, b in zip(fast, ref)) < TOL
    assert np.mean([img[..., 3].mean() for img in ref]) > 0.005  # not empty (the far splats are faint at 32²)


def test_small_form_depth(monkeypatch):
    scene, batch = _wall(), CASES["wall"][1]()
    images, depths = _render(monkeypatch, scene, batch, FORM_TOL, depth=True)
    ref_images, ref_depths = render_reference(scene, batch, with_depth=True)
    covered = ref_images[0][..., 3] > 0.01
    assert covered.mean() > 0.5
    np.testing.assert_allclose(depths[0][covered], ref_depths[0][covered], rtol=1e-3)
    assert np.abs(images[0] - ref_images[0]).max() < TOL
