"""core/probe/local_mix.py, the numpy twin of the local-light group's engine paths (the group itself is checked
against it in tests/test_blender_probes.py)."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core.probe import local_mix
from gs_ibl_addon.core.probe.grid import eval_irradiance


def _normals(n: int, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("engine", ["CYCLES", "EEVEE"])
def test_mix_gives_the_mesh_its_light_with_a_non_negative_emission(engine):
    """Wherever H >= 0 the rendered diffuse is H exactly, s lies in 0..1 and the emission is >= 0 (what EEVEE
    can show); where H is above the World in every channel s is 1 (the user's shader untouched)."""
    rng = np.random.default_rng(3)
    n = _normals(4000, 1)
    world = np.zeros((9, 3))
    world[0] = (0.6, 0.5, 0.4)
    world[1:] = rng.uniform(-0.08, 0.08, (8, 3))
    delta = np.zeros((9, 3))
    delta[0] = (-0.3, 0.2, 0.05)
    delta[1:4] = rng.uniform(-0.05, 0.05, (3, 3))
    here = eval_irradiance(world + delta, n)
    assert here.min() > 0
    base = local_mix.world_diffuse(world, n, engine)
    s, emit = local_mix.mix(here, base)
    assert s.min() >= 0 and s.max() <= 1 and emit.min() >= -1e-12
    np.testing.assert_allclose(local_mix.shaded(world, here, n, engine, albedo=0.8), 0.8 * here, rtol=1e-12)
    assert np.all(s < 1.0)  # darker red everywhere: the user's shader is dimmed
    s_up, _ = local_mix.mix(eval_irradiance(world + np.abs(delta), n), base)
    brighter = np.all(eval_irradiance(world + np.abs(delta), n) >= base, axis=-1)
    assert brighter.mean() > 0.5 and np.all(s_up[brighter] == 1.0)


def test_eevee_world_is_the_order_one_part_clamped():
    """EEVEE's World light: the first four monomial terms, at least 0; a World with no order-2 part is the same in
    both engines."""
    n = _normals(500, 2)
    w = np.zeros((9, 3))
    w[0], w[2] = 0.3, (0.15, 0.2, 0.1)  # a z slope EEVEE keeps (2/3 x 0.3 >= 0.2)
    e = local_mix.world_diffuse(w, n, "EEVEE")
    np.testing.assert_allclose(e, np.maximum(eval_irradiance(w, n), 0.0), atol=1e-12)
    w[6] = 0.1
    np.testing.assert_allclose(local_mix.world_diffuse(w, n, "EEVEE"), e, atol=1e-12)
    assert not np.allclose(local_mix.world_diffuse(w, n, "CYCLES"), e)


def test_eevee_derings_a_steep_world():
    """EEVEE scales every channel's order-1 band by one factor when any channel's largest L1 component would make
    its lobe negative (spherical_harmonics_dering): f = min_c 2/3 a0 / max_i |a_i|; our model of its light follows."""
    w = np.zeros((9, 3))
    w[0] = (0.3, 0.3, 0.6)
    w[1], w[2], w[3] = (0.05, 0.0, 0.1), (0.5, 0.1, -0.2), (0.0, 0.3, 0.1)  # red limits: 2/3 x 0.3 / 0.5 = 0.4
    order1 = local_mix.eevee_world_order1(w)
    np.testing.assert_allclose(order1[0], w[0])
    np.testing.assert_allclose(order1[1:], 0.4 * w[1:4])
    n = _normals(300, 4)
    np.testing.assert_allclose(local_mix.world_diffuse(w, n, "EEVEE"),
                               np.maximum(order1[0] + n[:, [1, 2, 0]] @ order1[1:], 0.0), atol=1e-12)
    # EEVEE's own test in radiance SH terms: L0 Y00 against the largest L1 coefficient times Y1, per channel
    c0 = w[0] / 0.282094792
    c1 = np.abs(w[1:4]) / (2.0 / 3.0 * 0.488602512)
    assert np.isclose(min(1.0, float((c0 / c1.max(0) * 0.282094792 / 0.488602512).min())), 0.4)
    black = np.zeros((9, 3))
    np.testing.assert_array_equal(local_mix.eevee_world_order1(black), black[:4])
