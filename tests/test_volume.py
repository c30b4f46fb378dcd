"""The light volume's layout and lookup (core/probe/volume.py, issue 37): octahedral maps, their atlas and the node
group's numpy twin, against plain references and analytic fields. No render here (test_volume_bake.py bakes)."""
import numpy as np
import pytest

from gs_ibl_addon.core.probe import volume as vol
from gs_ibl_addon.core.probe.grid import GridSpec
from gs_ibl_addon.core.synthetic import fibonacci_sphere

SPEC = GridSpec((-1.0, -0.5, 0.0), (2.0, 1.5, 1.0), (4, 3, 2))


def _dirs(n=2000, seed=0):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    axes = np.vstack([np.eye(3), -np.eye(3), [[1, 1, 0], [1, -1, 0], [-1, 0, 0.0], [0.3, 0.0, -0.7]]])
    return np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), axes / np.linalg.norm(axes, axis=1,
                                                                                           keepdims=True)])


def test_octahedral_round_trip_and_range():
    d = _dirs()
    uv = vol.oct_encode(d)
    assert np.all(np.abs(uv) <= 1 + 1e-12)
    assert np.allclose(vol.oct_decode(uv), d, atol=1e-12)
    uv2 = np.random.default_rng(1).uniform(-1, 1, (2000, 2))
    assert np.allclose(vol.oct_encode(vol.oct_decode(uv2)), uv2, atol=1e-9)
    # the interface's rule, spelled out for two lower-hemisphere directions (sign(0) = +1)
    assert np.allclose(vol.oct_encode([[0.0, 0.0, -1.0]]), [[1.0, 1.0]])
    # p = (0.5, -0.25) folded: (1 - |p.y|, 1 - |p.x|) sign(p) = (0.75, -0.5)
    assert np.allclose(vol.oct_encode([[0.5, -0.25, -0.25]]), [[0.75, -0.5]])


def test_the_fold_edges_and_corners():
    v = np.linspace(-1, 1, 41)
    for side in (-1.0, 1.0):
        edge = np.stack([np.full_like(v, side), v], -1)
        assert np.allclose(vol.oct_decode(edge), vol.oct_decode(edge * [1, -1]), atol=1e-12)
        edge = np.stack([v, np.full_like(v, side)], -1)
        assert np.allclose(vol.oct_decode(edge), vol.oct_decode(edge * [-1, 1]), atol=1e-12)
    corners = np.array([[1, 1], [-1, 1], [1, -1], [-1, -1.0]])
    assert np.allclose(vol.oct_decode(corners), [0, 0, -1])


def test_border_texels_are_the_texels_across_the_fold():
    """Each border texel holds the value of the map texel whose centre is the mirror of the border texel's centre
    across the edge: the same direction as the point half a texel beyond the edge mirrored back."""
    n = 5
    m = np.arange(n * n, dtype=float).reshape(n, n, 1)
    b = vol.add_border(m)[..., 0]
    assert np.array_equal(b[1:-1, 1:-1], m[..., 0])
    assert np.array_equal(b[1:-1, 0], m[::-1, 0, 0]) and np.array_equal(b[1:-1, -1], m[::-1, -1, 0])
    assert np.array_equal(b[0, 1:-1], m[0, ::-1, 0]) and np.array_equal(b[-1, 1:-1], m[-1, ::-1, 0])
    assert (b[0, 0], b[0, -1], b[-1, 0], b[-1, -1]) == (m[-1, -1, 0], m[-1, 0, 0], m[0, -1, 0], m[0, 0, 0])


def test_bilinear_lookup_is_seamless_across_the_fold():
    """A lookup just either side of an edge of the map (the equator folded, and the u, v axes of the lower half)
    changes by no more than the step size: the border continues the map across every fold."""
    rng = np.random.default_rng(3)
    maps = np.broadcast_to(rng.normal(size=(vol.IRR, vol.IRR, 3)), (1, vol.IRR, vol.IRR, 3))
    eps = 1e-7
    phi = rng.uniform(0, 2 * np.pi, 500)
    # the lower hemisphere's fold lines: z = 0 (the square's diamond), x = 0 and y = 0 (the square's edges)
    seams = [lambda s: np.stack([np.cos(phi), np.sin(phi), np.full_like(phi, s * eps)], -1),
             lambda s: np.stack([np.full_like(phi, s * eps), np.cos(phi), -np.abs(np.sin(phi))], -1),
             lambda s: np.stack([np.cos(phi), np.full_like(phi, s * eps), -np.abs(np.sin(phi))], -1)]
    m = np.broadcast_to(maps, (len(phi), vol.IRR, vol.IRR, 3))
    for seam in seams:
        a, b = vol.bilinear_map(m, seam(1.0)), vol.bilinear_map(m, seam(-1.0))
        assert np.abs(a - b).max() < 1e-4


def test_bilinear_matrix_is_the_lookup():
    d = _dirs(500)
    n = 7
    maps = np.random.default_rng(4).normal(size=(n, n, 3))
    want = vol.bilinear_map(np.broadcast_to(maps, (len(d), n, n, 3)), d)
    assert np.allclose(vol.bilinear_matrix(n, d) @ maps.reshape(-1, 3), want, atol=1e-12)


def test_atlas_layout():
    v = vol.synthetic_volume(SPEC, wall_x=0.7)
    irr, vis = vol.pack_atlas(v)
    cols, rows = vol.atlas_tiles(SPEC.count)
    assert (cols, rows) == (5, 5)
    assert irr.shape == (rows * (vol.IRR + 2), cols * (vol.IRR + 2), 3) and irr.dtype == np.float32
    assert vis.shape == (rows * (vol.VIS + 2), cols * (vol.VIS + 2), 3)
    c = vol.shader_constants(SPEC)
    assert c["irradiance_size"] == (irr.shape[1], irr.shape[0]) and c["visibility_size"] == (vis.shape[1],
                                                                                             vis.shape[0])
    # probe (ix, iy, iz) = (1, 2, 1): i = 1 + 4 (2 + 3) = 21 -> tile column 1, tile row 4 (rows from the bottom)
    i, t = 21, vol.IRR + 2
    tile = irr[4 * t + 1:4 * t + 1 + vol.IRR, 1 * t + 1:1 * t + 1 + vol.IRR]
    assert np.array_equal(tile, v.irradiance[1, 2, 1].astype(np.float32))
    assert np.allclose(vol.probe_positions(SPEC)[i], SPEC.points()[1, 2, 1])
    assert np.array_equal(vol.grid_maps(vol.flat_maps(v.moments), SPEC.shape), v.moments)
    assert np.all(vis[..., 2] == 0) and np.allclose(vis[..., 1], vis[..., 0] ** 2, rtol=1e-6)


@pytest.mark.parametrize("visibility", [True, False])
def test_packed_lookup_is_the_reference(visibility):
    """sample_packed (the node group's twin, float32 images) == sample (the unpacked maps), inside and outside the
    box, with a wall the visibility must see."""
    v = vol.synthetic_volume(SPEC, wall_x=0.7)
    rng = np.random.default_rng(5)
    pts = rng.uniform([-1.5, -1.0, -0.5], [2.5, 2.0, 1.5], (3000, 3))
    nrm = rng.normal(size=(3000, 3))
    irr, vis = vol.pack_atlas(v)
    got = vol.sample_packed(irr, vis, SPEC, pts, nrm, visibility)
    want = vol.sample(v, pts, nrm, visibility)
    assert np.abs(got - want).max() < 2e-5 * np.abs(want).max()


def test_a_field_of_direction_alone_is_reproduced_everywhere():
    """Every probe holding the same E(n): the weights cancel, the lookup is the map's bilinear interpolation of a
    smooth field (point-sampled texels here: the octahedral folds' kinks cost up to 2% of a linear field)."""
    sky = lambda p, n: np.stack([0.6 + 0.3 * n[..., 2], 0.5 + 0.1 * n[..., 0], 0.4 - 0.2 * n[..., 1]], -1)  # noqa
    v = vol.synthetic_volume(SPEC, sky, wall_x=0.7)
    rng = np.random.default_rng(6)
    pts = rng.uniform(SPEC.lo, SPEC.hi, (2000, 3))
    nrm = fibonacci_sphere(2000)
    err = np.abs(vol.sample(v, pts, nrm) - sky(pts, nrm))
    assert err.max() < 0.025 and err.mean() < 0.003


def test_a_ramp_in_position_is_interpolated():
    """At a node the node's own map; midway between two x layers, with normals across x, the corner pairs weigh alike
    and the ramp (0.5 + 0.1 x) comes out as the mean of the two layers; along a line in x it rises monotonically."""
    v = vol.synthetic_volume(SPEC)
    bias = vol.NORMAL_BIAS * vol.spec_spacing(SPEC)
    nodes = SPEC.points().reshape(-1, 3)
    up = np.tile([0.0, 0.0, 1.0], (len(nodes), 1))
    at = vol.sample(v, nodes - bias * up, up, visibility=False)
    assert np.allclose(at[:, 0], 0.5 + 0.1 * nodes[:, 0], atol=1e-9)
    rng = np.random.default_rng(7)
    x = rng.choice(SPEC.axis_points(0)[:-1], 400) + 0.5  # the x nodes are 1 m apart
    pts = np.stack([x, rng.uniform(-0.5, 1.5, 400), rng.uniform(0.0, 1.0, 400)], -1)
    normals = np.tile([0.0, 0.0, 1.0], (400, 1))
    got = vol.sample(v, pts - bias * normals, normals, visibility=False)
    assert np.allclose(got[:, 0], 0.5 + 0.1 * x, atol=1e-9)
    line = np.stack([np.linspace(-1, 2, 301), np.full(301, 0.3), np.full(301, 0.4)], -1)
    ramp = vol.sample(v, line, np.tile([0.0, 0.6, 0.8], (301, 1)), visibility=False)[:, 0]
    assert np.all(np.diff(ramp) > 0) and abs(ramp[0] - 0.4) < 1e-9 and abs(ramp[-1] - 0.7) < 1e-9


def test_visibility_keeps_light_behind_a_wall_out():
    """Probes beyond a wall (x > 0.9) hold bright light, those before it dark; points 0.2-0.35 m before the wall,
    in cells whose far corners are beyond it, see only the dark probes with visibility, a leak of the bright ones
    without. (The normal bias moves a point 0.125 m here: facing the wall from within ~0.1 m light leaks.)"""
    spec = GridSpec((0.0, 0.0, 0.0), (1.5, 1.0, 1.0), (4, 3, 3))
    bright = lambda p, n: np.where(p[..., :1] > 0.9, 10.0, 0.1) * np.ones(3)  # noqa: E731
    v = vol.synthetic_volume(spec, bright, wall_x=0.9)
    rng = np.random.default_rng(8)
    pts = np.stack([rng.uniform(0.55, 0.7, 200), rng.uniform(0.1, 0.9, 200), rng.uniform(0.1, 0.9, 200)], -1)
    nrm = np.concatenate([np.zeros((200, 1)), rng.normal(size=(200, 2))], 1)
    with_vis = vol.sample(v, pts, nrm)
    without = vol.sample(v, pts, nrm, visibility=False)
    assert np.all(np.abs(with_vis - 0.1) < 0.002)
    assert np.all(without[:, 0] > 0.5)


# ------------------------------------------------------------------------------------------------------------------
# Bricks: cells of the grid holding (r + 1)^3 probes of their own (volume_refine.py chooses them)

CUBE = GridSpec((0.0, 0.0, 0.0), (3.0, 2.0, 2.0), (4, 3, 3))


def _refine(levels):
    r = np.ones(vol.cell_shape(CUBE), int)
    for (cx, cy, cz), k in levels.items():
        r[cx, cy, cz] = k
    return r


def test_brick_layout_and_cells_image():
    refine = _refine({(1, 0, 1): 2, (2, 1, 0): 4})
    keys = vol.brick_keys(CUBE, refine)
    assert len(keys) == 27 + 125
    bases = vol.brick_bases(refine)
    # cell order is cx fastest: (2, 1, 0) = cell 5 comes before (1, 0, 1) = cell 7
    assert bases[2, 1, 0] == 0 and bases[1, 0, 1] == 125
    pos = vol.key_positions(CUBE, keys)
    assert np.allclose(pos[0], CUBE.points()[2, 1, 0]) and np.allclose(pos[124], CUBE.points()[3, 2, 1])
    assert np.allclose(pos[125 + 13], (CUBE.points()[1, 0, 1] + CUBE.points()[2, 1, 2]) / 2)  # the cell's centre
    v = vol.synthetic_volume(CUBE, refine=refine)
    img = vol.pack_cells(v)
    assert img.shape == (3, 4, 3)  # 3 x 2 x 2 cells: 4 texels wide, 3 high
    assert tuple(img[1, 1, :2]) == (0.0, 4.0) and tuple(img[1, 3, :2]) == (125.0, 2.0)
    c = vol.shader_constants(CUBE, v.tiles)
    irr, vis = vol.pack_atlas(v)
    assert c["irradiance_size"] == (irr.shape[1], irr.shape[0]) and c["cells_size"] == (4, 3)


def test_a_packed_volume_unpacks_to_itself():
    """unpack_volume reads the three images back into the volume they were packed from (what a reopened file's
    growth starts from), with bricks and without."""
    for refine in (_refine({(1, 0, 1): 2, (2, 1, 0): 4}), None):
        v = vol.synthetic_volume(CUBE, _bump, refine=refine)
        irr, vis = vol.pack_atlas(v)
        back = vol.unpack_volume(irr, vis, vol.pack_cells(v), CUBE, v.tiles)
        assert back.tiles == v.tiles and np.array_equal(back.cells, v.cells)
        for a, b in zip(back.all_maps(), v.all_maps()):
            assert np.array_equal(a, np.asarray(b, np.float32))
    with pytest.raises(ValueError, match="maps"):
        vol.unpack_volume(irr, vis, vol.pack_cells(v), CUBE, v.tiles + 3)


def _bump(p, n):
    """A light that peaks inside one cell (a lamp's 1/d^2 softened): linear interpolation between the grid's nodes
    misses it."""
    d2 = np.sum((p - [1.4, 0.6, 1.3]) ** 2, -1)
    e = 0.3 + 1.0 / (0.15 + d2)
    return np.stack([e * (1.0 + 0.2 * n[..., 2]), e, 0.5 * e], -1)


@pytest.mark.parametrize("visibility", [True, False])
def test_bricks_packed_lookup_is_the_reference(visibility):
    refine = _refine({(1, 0, 1): 2, (1, 0, 0): 4, (0, 1, 1): 2})
    v = vol.synthetic_volume(CUBE, _bump, wall_x=2.2, refine=refine)
    rng = np.random.default_rng(8)
    pts = rng.uniform([-0.3, -0.3, -0.3], [3.3, 2.3, 2.3], (3000, 3))
    nrm = rng.normal(size=(3000, 3))
    irr, vis = vol.pack_atlas(v)
    got = vol.sample_packed(irr, vis, CUBE, pts, nrm, visibility, cells=vol.pack_cells(v))
    want = vol.sample(v, pts, nrm, visibility)
    assert np.abs(got - want).max() < 2e-5 * np.abs(want).max()


def test_bricks_follow_light_the_grid_misses():
    """Around the bump, a brick of r = 4 in its cell and r = 2 in the cells beside it: the lookup's error against
    the exact field falls severalfold where the bricks are and is unchanged elsewhere; at a brick's node it is the
    node's own light."""
    refine = _refine({(1, 0, 1): 4, (0, 0, 1): 2, (1, 0, 0): 2, (1, 1, 1): 2})
    plain, bricked = vol.synthetic_volume(CUBE, _bump), vol.synthetic_volume(CUBE, _bump, refine=refine)
    rng = np.random.default_rng(9)
    pts = rng.uniform([1.05, 0.05, 1.05], [1.95, 0.95, 1.95], (1500, 3))  # inside cell (1, 0, 1), off its faces
    nrm = fibonacci_sphere(1500)
    exact = _bump(pts, nrm)

    def err(v, p):
        return np.abs(vol.sample(v, p, nrm) - _bump(p, nrm)).mean() / np.abs(exact).mean()
    e_plain, e_bricked = err(plain, pts), err(bricked, pts)
    assert e_bricked < 0.25 * e_plain, (e_plain, e_bricked)
    far = rng.uniform([2.1, 1.1, 0.1], [2.9, 1.9, 0.9], (1500, 3))  # cell (2, 1, 0): no brick
    assert np.isclose(err(plain, far), err(bricked, far), rtol=1e-9)
    node = vol.key_positions(CUBE, np.array([[6, 1, 6]]))  # a brick node inside cell (1, 0, 1)
    n = fibonacci_sphere(50)
    p = node - vol.NORMAL_BIAS * vol.spec_spacing(CUBE) * n  # the lookup moves it back onto the node
    assert np.allclose(vol.sample(bricked, p, n), _bump(np.repeat(node, 50, 0), n), rtol=0.02)


def test_key_codes_are_places():
    """Brick keys as one int64 a place (volume.key_codes): a round trip, the key tuples' order, and find_codes
    keeping the last of a repeated place as a dict filled in order would."""
    rng = np.random.default_rng(0)
    keys = rng.integers(-50, 200, (500, 3))
    codes = vol.key_codes(keys)
    assert np.array_equal(vol.code_keys(codes), keys)
    by_tuple = sorted(range(len(keys)), key=lambda i: tuple(keys[i]))
    assert np.array_equal(np.argsort(codes, kind="stable"), by_tuple)
    table = np.concatenate([codes, codes[:10]])
    assert np.array_equal(vol.find_codes(table, codes[:20]), np.r_[500:510, 10:20])
    with pytest.raises(KeyError):
        vol.find_codes(codes, vol.key_codes([[999, 999, 999]]))  # a place the table does not hold
