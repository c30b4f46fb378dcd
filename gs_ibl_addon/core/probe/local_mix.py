"""How the local-light group turns a mesh's own light into a shader: the numpy twin of blender/local_light.py.

The user's shader already sees the World's diffuse light B(n); the mesh should see H(n) = E(n) + D(n): the World
probe's irradiance (its irradiance image, E/pi: what Cycles integrates from that World) plus the mesh's difference
D (order-2 SH of its probes minus the World probe's, baked alike). Adding Emission(albedo (H - B)) is right only
where H >= B: EEVEE clamps negative emission to 0 (measured: Emission -0.3 renders 0 in EEVEE, -0.3 in Cycles), so a mesh darker than the
World (a far corner) stayed as bright as the World. So the user's shader is first scaled by the largest s in 0..1
that keeps every channel's remainder non-negative:

    s = clamp(min_c H_c / B_c, 0, 1),   surface = s x user + Emission(albedo x (H - s B))

whose diffuse part is albedo x H wherever H is non-negative; specular and the rest of the user's material dim with
the diffuse where the mesh's light is darker than the World's. In Blender the emission is also multiplied by the
mesh's own ambient occlusion (Only Local), standing in for the shadows the engine traces for the user's shader and
not for emission; on a convex mesh it is 1, which is what this twin models.

B differs by engine. Cycles integrates the World image: B = E, and H = E + D. EEVEE lights from an order-1 SH of
the World (eevee_spherical_harmonics_lib.glsl, spherical_harmonics_evaluate_lambert: L0 + 2/3 L1, clamped at 0)
once the World's sun extraction is off (World.sun_threshold = 0, blender/world.py): B = max(0, the first four
monomial terms of W, the World probe's order-2 coefficients), and H = W + D, our order-2 light. Checked: on smooth
Worlds (radiance a + b z, a + c z^2) EEVEE's own light is this B within 1% and the group's result H within 0.5%.
Measured, not explained: for the sample room's World (a lamp of radiance 40, a window) EEVEE's own light falls
1-3% (a bpy 5.0 view of the window side) to ~10% (the five-place bench, bpy 5.3) below B, red most; aiming EEVEE
at E + D put the five places' spheres 4-14% below native Cycles, at W + D 0-6% (docs/blender.md).
"""
from __future__ import annotations

import numpy as np

from .grid import eval_irradiance, monomials

EPS = 1e-6  # a World channel darker than this is treated as black: any light of ours adds to it
L1_TERMS = 4  # monomials 1, y, z, x: the order-1 part of an order-2 irradiance


def world_diffuse(world: np.ndarray, normals: np.ndarray, engine: str,
                  irradiance: np.ndarray | None = None) -> np.ndarray:
    """E(n)/pi the user's shader gets from the World in ``engine`` ("CYCLES" or "EEVEE"): world (9, 3) monomial
    coefficients, normals (..., 3) -> (..., 3); ``irradiance``: the World's irradiance at those normals (Cycles';
    default: the coefficients' own)."""
    w = np.asarray(world, np.float64)
    if engine == "CYCLES":
        return eval_irradiance(w, normals) if irradiance is None else np.asarray(irradiance, np.float64)
    return np.maximum(monomials(normals)[..., :L1_TERMS] @ w[:L1_TERMS], 0.0)


def mix(here: np.ndarray, base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s (...,), emission (..., 3) per unit albedo): the user's shader scale and what is emitted on top."""
    s = np.clip(np.min(here / np.maximum(base, EPS), axis=-1), 0.0, 1.0)
    return s, here - s[..., None] * base


def shaded(world: np.ndarray, here: np.ndarray, normals: np.ndarray, engine: str, albedo: float = 1.0,
           irradiance: np.ndarray | None = None) -> np.ndarray:
    """What a diffuse mesh of ``albedo`` renders, given H(n) ``here`` (..., 3) at its normals (E + D in Cycles,
    W + D in EEVEE): s x albedo x B + the emission, clamped at 0 as EEVEE does (Cycles keeps a negative remainder)."""
    base = world_diffuse(world, normals, engine, irradiance)
    s, emit = mix(here, base)
    if engine != "CYCLES":
        emit = np.maximum(emit, 0.0)
    return albedo * (s[..., None] * base + emit)
