"""More than one probe (issue 17 part 3): the variation estimate and the probe grid, against numpy references.

The synthetic scene with a known gradient: a closed shell (radius 10) whose splats' colour is a + b z/R, so a
point above the centre sees more of the bright top. The reference radiance seen from any point is where the ray
leaves the sphere, projected onto order-2 SH by quadrature; probes rendered by the GPU must match it, and the
variation estimate built on them must match the reference's.
"""
import numpy as np
import pytest

from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.probe import grid as pg
from gs_ibl_addon.core.probe.sh_project import sh_basis_any, sh_irradiance
from gs_ibl_addon.core.probe.variation import box_points, estimate_variation, variation_from_sh
from gs_ibl_addon.core.render.renderer import SplatRenderer

R = 10.0
A = np.array([0.5, 0.45, 0.4])
B = np.array([0.4, 0.3, 0.1])


def gradient(d):
    return A[None] + d[:, 2:3] * B[None]


def reference_sh(point, n=40000):
    """Order-2 radiance SH seen from ``point`` inside the gradient shell (quadrature over Fibonacci directions)."""
    w = synthetic.fibonacci_sphere(n)
    p = np.asarray(point, np.float64)
    pw = w @ p
    t = -pw + np.sqrt(pw * pw - p @ p + R * R)  # where the ray leaves the sphere
    hit = p + t[:, None] * w
    return sh_basis_any(w, 2).T @ gradient(hit / R) * (4 * np.pi / n)


@pytest.fixture(scope="module")
def shell_renderer():
    r = SplatRenderer(synthetic.shell_scene(gradient, 80000, radius=R))
    yield r
    r.close()


def test_monomials_evaluate_the_sh_irradiance():
    rng = np.random.default_rng(1)
    sh = rng.normal(size=(9, 3))
    n = synthetic.fibonacci_sphere(50)
    want = sh_irradiance(sh, n, clamp=False)
    got = pg.eval_irradiance(pg.monomial_coefficients(sh), n)
    assert np.allclose(got, want, atol=1e-12)


def test_trilinear_interpolation_and_the_packed_image_agree():
    """The shader's layout (two bilinear lookups per coefficient, z blended by hand) gives the trilinear
    interpolation of the grid; both reproduce a field linear in position exactly, and clamp outside the box."""
    spec = pg.GridSpec((-1.0, -2.0, 0.0), (3.0, 2.0, 1.5), (4, 3, 5))
    rng = np.random.default_rng(2)
    values = rng.normal(size=(*spec.shape, 9, 3))
    pts = rng.uniform([-1.5, -2.5, -0.5], [3.5, 2.5, 2.0], size=(500, 3))
    ref = pg.interpolate(values, spec, pts)
    packed = pg.pack_grid(values)
    assert packed.shape == (5 * 3, 9 * 4, 3)
    got = pg.sample_packed(packed, spec, pts)
    assert np.abs(got - ref).max() < 1e-5  # float32 image
    # nodes are hit exactly, and a linear field is reproduced between them
    nodes = spec.points().reshape(-1, 3)
    assert np.allclose(pg.interpolate(values, spec, nodes), values.reshape(-1, 9, 3))
    lin = spec.points() @ np.array([0.3, -0.2, 0.7])
    inside = rng.uniform(spec.lo, spec.hi, size=(200, 3))
    assert np.allclose(pg.interpolate(lin, spec, inside), inside @ np.array([0.3, -0.2, 0.7]))
    # a single node along an axis: constant along it, the packed image still right
    flat = pg.GridSpec((0, 0, 0), (1, 1, 1), (1, 2, 1))
    v1 = rng.normal(size=(1, 2, 1, 9, 3))
    assert np.abs(pg.sample_packed(pg.pack_grid(v1), flat, pts) - pg.interpolate(v1, flat, pts)).max() < 1e-5


def test_bad_grid_is_refused():
    with pytest.raises(ValueError, match="resolution"):
        pg.GridSpec((0, 0, 0), (1, 1, 1), (0, 2, 2))
    with pytest.raises(ValueError, match="hi"):
        pg.GridSpec((0, 0, 0), (1, -1, 1), (2, 2, 2))


def test_probes_and_variation_match_the_reference_gradient(shell_renderer):
    """Probes at a box's centre and corners match the quadrature reference; the variation estimate from them
    matches the reference's, says 'use a per-object probe or a grid' when over the tolerance, and a small box at
    the centre is within it."""
    lo, hi = (-2.0, -2.0, -3.0), (2.0, 2.0, 3.0)
    pts = box_points(lo, hi)
    want = np.stack([reference_sh(p) for p in pts])
    got = pg.bake_sh_points(shell_renderer, pts)
    e_want = pg.eval_irradiance(pg.monomial_coefficients(want)[:, None], synthetic.fibonacci_sphere(64)[None])
    e_got = pg.eval_irradiance(pg.monomial_coefficients(got)[:, None], synthetic.fibonacci_sphere(64)[None])
    rel = np.abs(e_got - e_want).max() / e_want.mean()
    print(f"\nprobe irradiance vs reference: max {100 * rel:.2f}% of the mean")
    assert rel < 0.04  # measured 3.0%: oblique splats of the shell drawn in per-splat order (docs/stability.md)
    v_ref = variation_from_sh("box", want, pts)
    v = estimate_variation(shell_renderer, {"box": (lo, hi), "small": ((-0.1,) * 3, (0.1,) * 3)})
    print(f"variation: GPU {100 * v[0].variation:.2f}%, reference {100 * v_ref.variation:.2f}%, "
          f"small box {100 * v[1].variation:.2f}%")
    # measured 19.8% against 17.7%: the same bias, a little stronger at the box's bottom corners
    assert abs(v[0].variation - v_ref.variation) < 0.15 * v_ref.variation
    assert v[0].exceeds(0.05) and "use a per-object probe or a grid" in v[0].message(0.05)
    assert abs(v[0].corner[2]) == 3.0  # the gradient is along z: a top or bottom corner differs most
    assert not v[1].exceeds(0.05) and "one probe is enough" in v[1].message(0.05)


def test_grid_interpolates_the_gradient_between_probes(shell_renderer):
    """A 2 x 2 x 3 grid over a box: its interpolated irradiance at points between the nodes is within 5% of a probe
    baked at each point. The field is not linear in position: the same grid of reference probes interpolates
    within 2.1% of the reference at these points; the rest is the probes' own 2-3% (above)."""
    spec = pg.GridSpec((-2.0, -2.0, -3.0), (2.0, 2.0, 3.0), (2, 2, 3))
    sh = pg.bake_grid(shell_renderer, spec)
    d = pg.monomial_coefficients(sh)
    rng = np.random.default_rng(3)
    pts = rng.uniform(spec.lo, spec.hi, size=(6, 3))
    at = pg.sample_packed(pg.pack_grid(d), spec, pts)
    direct = pg.monomial_coefficients(pg.bake_sh_points(shell_renderer, pts))
    normals = synthetic.fibonacci_sphere(64)
    e_grid = pg.eval_irradiance(at[:, None], normals[None])
    e_direct = pg.eval_irradiance(direct[:, None], normals[None])
    rel = np.abs(e_grid - e_direct).max() / e_direct.mean()
    print(f"\ngrid vs a probe at the point: max {100 * rel:.2f}% of the mean")
    assert rel < 0.05
