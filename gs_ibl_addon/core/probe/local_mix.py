"""How the local-light group turns a mesh's own light into a shader: the numpy twin of blender/lighting/local_light.py.

The user's shader already sees the World's diffuse light B(n); the mesh should see H(n) = E(n) + D(n): the World
probe's irradiance (its irradiance image, E/pi: what Cycles integrates from that World) plus the mesh's difference D
(order-2 SH of its probes minus the World probe's, baked alike). Adding Emission(albedo (H - B)) is right only where
H >= B: EEVEE clamps negative emission to 0 (measured: Emission -0.3 renders 0 in EEVEE, -0.3 in Cycles), so a mesh
darker than the World (a far corner) stayed as bright as the World. So the user's shader is first scaled by the
largest s in 0..1 that keeps every channel's remainder non-negative:

    s = clamp(min_c H_c / B_c, 0, 1),   surface = s x user + Emission(albedo x (H - s B))

whose diffuse part is albedo x H wherever H is non-negative; specular and the rest of the user's material dim with
the diffuse where the mesh's light is darker than the World's. In Blender the emission is also multiplied by the
mesh's own ambient occlusion (Only Local), standing in for the shadows the engine traces for the user's shader and
not for emission; on a convex mesh it is 1, which is what this twin models.

Cycles keeps a negative emission, so there the (1 - s) of the user's shader that s takes away is replaced by a plain
diffuse of the albedo (the same albedo the emission assumes: the user's diffuse colour, or the group's grey for a
shader it does not know), and the emission is the signed difference H - B alone:

    surface = s x user + (1 - s) x Diffuse(albedo) + Emission(albedo x (H - B))

The World's diffuse light then stays traced, with its shadows, whatever s is (the user's specular still dims by s,
as in EEVEE), and the AO stand-in scales only the mesh's difference D: with (1 - s) B inside the emission, a far
corner's Suzanne (s ~ 0.5 in blue) lost the traced World's shadows on that part and rendered 3.4% below native
Cycles, 1.4% with this (2026-12-03).

B differs by engine. Cycles integrates the World image: B = E, and H = E + D. EEVEE lights from an order-1 SH of
the World (eevee_spherical_harmonics_lib.glsl, spherical_harmonics_evaluate_lambert: L0 + 2/3 L1, clamped at 0)
once the World's sun extraction is off (World.sun_threshold = 0, blender/lighting/world.py), and H = W + D, our order-2
light. Before storing the World's order-1 SH, EEVEE "derings" it (spherical_harmonics_dering, applied to the
World's volume-probe brick): where any channel's largest L1 component exceeds what keeps that channel's lobe
non-negative, every channel's L1 band is scaled by one factor, f = min over channels of L0 Y00 / (max_i |L1_i|
Y1), which in our monomial terms is f = min_c 2/3 a0_c / max_i |a_ic|. So B = max(0, a0 + min(1, f) a.n), a
from the first four monomial terms of W (eevee_world_order1). Checked: on smooth Worlds (radiance a + b z,
a + c z^2) EEVEE's own light is this B within 1% and the group's result H within 0.5%. The sample room's World
(a lamp of radiance 40, a window) has f = 0.94 at the room's centre (blue limits it): before the dering was
modelled, EEVEE's own light fell 1-10% below an un-deringed B and the five places' spheres 1-7% below Cycles.
"""
from __future__ import annotations

import numpy as np

from .grid import eval_irradiance, monomials

EPS = 1e-6  # a World channel darker than this is treated as black: any light of ours adds to it
L1_TERMS = 4  # monomials 1, y, z, x: the order-1 part of an order-2 irradiance


def eevee_world_order1(world: np.ndarray) -> np.ndarray:
    """The (4, C) order-1 monomial coefficients (1, y, z, x) of EEVEE's World light for World coefficients
    ``world`` (9, C): the linear terms scaled by EEVEE's dering factor when it is below 1."""
    w = np.array(np.asarray(world, np.float64)[:L1_TERMS])
    slope = np.abs(w[1:]).max(axis=0)
    ratio = np.where(slope > 0.0, (2.0 / 3.0) * np.abs(w[0]) / np.maximum(slope, 1e-300), np.inf)
    w[1:] *= min(1.0, float(ratio.min()))
    return w


def world_diffuse(world: np.ndarray, normals: np.ndarray, engine: str,
                  irradiance: np.ndarray | None = None) -> np.ndarray:
    """E(n)/pi the user's shader gets from the World in ``engine`` ("CYCLES" or "EEVEE"): world (9, 3) monomial
    coefficients, normals (..., 3) -> (..., 3); ``irradiance``: the World's irradiance at those normals (Cycles';
    default: the coefficients' own)."""
    w = np.asarray(world, np.float64)
    if engine == "CYCLES":
        return eval_irradiance(w, normals) if irradiance is None else np.asarray(irradiance, np.float64)
    return np.maximum(monomials(normals)[..., :L1_TERMS] @ eevee_world_order1(w), 0.0)


def mix(here: np.ndarray, base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s (...,), emission (..., 3) per unit albedo): the user's shader scale and what EEVEE emits on top (Cycles
    emits here - base, shaded() says how)."""
    s = np.clip(np.min(here / np.maximum(base, EPS), axis=-1), 0.0, 1.0)
    return s, here - s[..., None] * base


def shaded(world: np.ndarray, here: np.ndarray, normals: np.ndarray, engine: str, albedo: float = 1.0,
           irradiance: np.ndarray | None = None) -> np.ndarray:
    """What a diffuse mesh of ``albedo`` renders, given H(n) ``here`` (..., 3) at its normals (E + D in Cycles,
    W + D in EEVEE): in EEVEE s x albedo x B + the emission, clamped at 0 as EEVEE does; in Cycles s x albedo x B +
    (1 - s) x albedo x B (the plain diffuse) + the signed emission H - B."""
    base = world_diffuse(world, normals, engine, irradiance)
    s, emit = mix(here, base)
    if engine == "CYCLES":
        return albedo * (s[..., None] * base + (1.0 - s[..., None]) * base + (here - base))
    return albedo * (s[..., None] * base + np.maximum(emit, 0.0))
