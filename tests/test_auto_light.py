"""The rule of Lighting Auto (core/probe/auto_light.py), on monomial coefficients with known answers."""
import numpy as np

from gs_ibl_addon.core.probe.auto_light import choose_light, measure_points, mesh_grid


def _uniform(level: float) -> np.ndarray:
    """Monomial coefficients (9, 3) of a light whose irradiance is ``level`` in every direction."""
    d = np.zeros((9, 3))
    d[0] = level
    return d


def test_the_world_a_probe_or_a_grid():
    world = _uniform(1.0)
    same = np.stack([_uniform(1.0)] * 9)
    assert choose_light("a", world, same, 0.05).kind == "world"
    brighter = np.stack([_uniform(1.3)] * 9)  # uniform across the mesh, 30% above the World's
    c = choose_light("b", world, brighter, 0.05)
    assert c.kind == "probe" and abs(c.offset - 0.3 / 1.3) < 1e-9 and c.variation < 1e-12
    varying = np.stack([_uniform(1.0)] + [_uniform(1.0 + 0.1 * i) for i in range(8)])
    c = choose_light("c", world, varying, 0.05)
    assert c.kind == "grid" and abs(c.variation - 0.7) < 1e-9
    assert "grid" in c.message() and "70%" in c.message()


def test_measure_points_and_grid_keep_off_the_floor():
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([1.0, 2.0, 0.5])  # a mesh resting on the floor at z = 0
    pts = measure_points(lo, hi)
    assert pts.shape == (9, 3) and np.allclose(pts[0], (lo + hi) / 2)
    # its lowest probes stand above the floor's splats: (1 - SHRINK) / 2 of its height, 3.75 cm here
    assert pts[1:, 2].min() > 0.03
    flat = mesh_grid([0, 0, 0], [1, 1, 0.01])  # a thin plate gets one node across its thickness
    assert flat.shape == (3, 3, 1)


def test_a_grid_reuses_the_measured_nodes():
    """A mesh's 3 x 3 x 3 grid holds its 9 measure points (centre and corners of the same shrunk box): the second
    batch renders only the other 18; a flat box (one node across) reuses its centre and four corners."""
    from gs_ibl_addon.core.probe.auto_light import measure_points, measured_nodes, mesh_grid
    lo, hi = np.array([0.2, -0.4, 1.0]), np.array([0.8, 0.3, 1.5])
    spec, pts = mesh_grid(lo, hi), measure_points(lo, hi)
    m = measured_nodes(spec, pts)
    assert (m >= 0).sum() == 9 and sorted(m[m >= 0].tolist()) == list(range(9))
    np.testing.assert_allclose(spec.points().reshape(-1, 3)[m >= 0], pts[m[m >= 0]], atol=1e-12)
    dense = mesh_grid(lo, hi, variation=1.5)  # light changing by more than its mean across it: 5 x 5 x 5
    md = measured_nodes(dense, pts)
    assert dense.shape == (5, 5, 5) and (md >= 0).sum() == 9 and (dense.lo, dense.hi) == (spec.lo, spec.hi)
    flat = mesh_grid(lo, np.array([0.8, 0.3, 1.0]))  # no height: one node along z
    mf = measured_nodes(flat, measure_points(lo, np.array([0.8, 0.3, 1.0])))
    assert flat.count == 9 and (mf >= 0).sum() == 5  # the centre and four corners; the edge middles are new


def test_the_batches_a_light_field_asks_for():
    """auto_light_batches on a known light (irradiance level 1 + x, uniform in direction; a bake is this function
    of the points): the first batch is the World probe's place and each mesh's measure points; a mesh across the
    light's change gets a grid whose second batch is only the nodes not measured, and every node holds the field;
    a mesh where x = 0 gets the World's light (level 1 at the World probe's place, x = 0)."""
    from gs_ibl_addon.core.probe.auto_light import auto_light_batches, run_batches

    def field(points):
        return np.stack([_uniform(1.0 + p[0]) for p in np.asarray(points)])

    asked = []

    def bake(points):
        asked.append(np.asarray(points))
        return field(points)
    boxes = [(np.array([-0.05, 0.0, 0.0]), np.array([0.05, 0.1, 0.1])),  # 8.5 cm across: 8.5% change
             (np.array([0.4, 0.0, 0.0]), np.array([1.4, 1.0, 1.0]))]  # x from 0.475 to 1.325
    light = run_batches(auto_light_batches((0.0, 0.0, 0.0), boxes, ["small", "wide"], 0.1), bake)
    assert [c.kind for c in light.choices] == ["world", "grid"]
    assert len(asked) == 2 and len(asked[0]) == 1 + 2 * 9 and np.allclose(asked[0][0], 0)
    spec, nodes = light.grids[1]
    assert spec.shape == (3, 3, 3) and len(asked[1]) == 27 - 9
    np.testing.assert_allclose(nodes.reshape(-1, 9, 3), field(spec.points().reshape(-1, 3)), atol=1e-12)
    inside = np.array([[0.9, 0.5, 0.5], [0.6, 0.2, 0.8]])
    np.testing.assert_allclose(light.coefficients_at(1, inside), field(inside), atol=1e-12)  # linear: exact
    np.testing.assert_allclose(light.coefficients_at(0, inside), field(np.zeros((2, 3))), atol=1e-12)
    # no mesh needs a grid: one batch
    asked.clear()
    light = run_batches(auto_light_batches((0.0, 0.0, 0.0), boxes[:1], ["small"], 0.1), bake)
    assert len(asked) == 1 and light.grids == {}
