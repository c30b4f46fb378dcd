"""Ground-truth irradiance: what every filter (numpy and GPU) is measured against.

``exact_irradiance`` integrates a radiance cube over every texel in float64 (the cube *is* the environment:
piecewise constant over texels, with exact texel solid angles), so its only approximation is the cosine
taken at texel centres. ``analytic_irradiance`` integrates a radiance *function* by Gauss-Legendre in
cos(theta) x uniform phi in each normal's own hemisphere frame, so a smooth function converges fast.
Both return E(n)/pi.
"""
from __future__ import annotations

from typing import Callable, Iterator

import numpy as np

from .. import cubemap
from .box import downsample_to_size, halving_sizes
from .sampling import split_alpha

# Elements of the (normals x texels) cosine block held at once: ~64 MB of float64.
_CHUNK_ELEMS = 1 << 23


def row_chunks(rows: int, row_size: int, budget: int) -> Iterator[slice]:
    """Slices of ``rows`` output rows, each of row_size elements, so that a chunk holds about ``budget`` elements."""
    step = max(1, budget // max(1, row_size))
    for start in range(0, rows, step):
        yield slice(start, start + step)


def _texel_sums(cube: np.ndarray, normals: np.ndarray,
                kernel: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """Per (..., 3) normal, a sum over every texel w of the cube (holes black), in float64 -> (..., C):
    ``kernel(n.w (M, T), texel solid angles (T,), radiance (T, C)) -> (M, C)`` for chunks of M normals."""
    rgb, _ = split_alpha(cube)
    n, c = rgb.shape[1], rgb.shape[3]
    w = cubemap.face_directions(n).reshape(-1, 3)
    dom = np.tile(cubemap.texel_solid_angles(n).reshape(-1), 6)
    lw = rgb.reshape(-1, c)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.empty((nrm.shape[0], c))
    for sl in row_chunks(nrm.shape[0], w.shape[0], _CHUNK_ELEMS):
        out[sl] = kernel(nrm[sl] @ w.T, dom, lw)
    return out.reshape(np.shape(normals)[:-1] + (c,))


def exact_irradiance(cube: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """E(n)/pi = (1/pi) sum_texels L * max(0, n.w) * dOmega for (..., 3) unit normals -> (..., C), float64."""
    def kernel(cos: np.ndarray, dom: np.ndarray, lw: np.ndarray) -> np.ndarray:
        np.maximum(cos, 0.0, out=cos)
        return cos @ (lw * dom[:, None] / np.pi)
    return _texel_sums(cube, normals, kernel)


def integration_size(face_size: int, downsample_to: int | None) -> int:
    """Face size the exact integral runs at: halved while above downsample_to and even (None: no downsampling)."""
    if downsample_to is None:
        return int(face_size)
    if downsample_to < 1:
        raise ValueError(f"exact irradiance: downsample_to must be >= 1 or None, got {downsample_to}")
    return halving_sizes(face_size, downsample_to)[-1]


def _integrated_rgb(cube: np.ndarray, downsample_to: int | None) -> np.ndarray:
    """The cube's RGB (holes black) at the face size the exact integral runs at."""
    rgb, _ = split_alpha(cube)
    return downsample_to_size(rgb, integration_size(rgb.shape[1], downsample_to))


def exact_irradiance_cube(cube: np.ndarray, size: int, downsample_to: int | None = None) -> np.ndarray:
    """Exact irradiance (E/pi) of a radiance cube at the texel centres of a (6, size, size) cube.

    downsample_to: first halve the faces (box.downsample_cube: solid-angle weighted, so every parent keeps its
    children's power) while they are above this size and even. Irradiance is a low-pass, so the only loss is
    the cosine taken at parent rather than child centres (measured in docs/accuracy.md); None keeps every texel.
    """
    return exact_irradiance(_integrated_rgb(cube, downsample_to), cubemap.face_directions(size))


def exact_irradiance_parts(cube: np.ndarray, size: int, downsample_to: int | None = None) -> np.ndarray:
    """(6, 6, size, size, C): [f] is the exact irradiance (E/pi) that face f's texels alone give, as
    exact_irradiance_cube integrates them (so the six parts sum to it). A change between two cubes splits this way
    into what each face's change does to the light (tolerance.ErrorModel.take_parts)."""
    rgb = _integrated_rgb(cube, downsample_to)
    n, c = rgb.shape[1], rgb.shape[3]
    w = cubemap.face_directions(n).reshape(6, -1, 3)
    lw = rgb.reshape(6, -1, c) * cubemap.texel_solid_angles(n).reshape(1, -1, 1) / np.pi
    normals = cubemap.face_directions(size).reshape(-1, 3)
    out = np.empty((6, normals.shape[0], c))
    for f in range(6):
        out[f] = np.maximum(normals @ w[f].T, 0.0) @ lw[f]
    return out.reshape(6, 6, size, size, c)


def _hemisphere_rule(n_mu: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    # Gauss-Legendre in mu = cos(theta) on [0, 1], midpoint in phi: local directions (S, 3) and weights mu*dmu*dphi.
    x, wx = np.polynomial.legendre.leggauss(n_mu)
    mu = 0.5 * (x + 1.0)
    wmu = 0.5 * wx
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    m, p = np.meshgrid(mu, phi, indexing="ij")
    st = np.sqrt(np.maximum(0.0, 1.0 - m * m))
    local = np.stack([st * np.cos(p), st * np.sin(p), m], -1).reshape(-1, 3)
    weight = (wmu[:, None] * m * (2.0 * np.pi / n_phi)).reshape(-1)
    return local, weight


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal (tangent, bitangent) for (M, 3) unit normals; stable everywhere (no pole singularity)."""
    n = np.asarray(normals, np.float64)
    helper = np.where(np.abs(n[:, 2:3]) < 0.999, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))
    t = np.cross(helper, n)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    return t, np.cross(n, t)


def to_world(local: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Directions (S, 3) about +Z -> (M, S, 3) in each of M frames (tangent t, bitangent b, normal n), each (M, 3)."""
    return local[None, :, 0:1] * t[:, None] + local[None, :, 1:2] * b[:, None] + local[None, :, 2:3] * n[:, None]


def analytic_irradiance(radiance: Callable[[np.ndarray], np.ndarray], normals: np.ndarray,
                        n_mu: int = 48, n_phi: int = 96) -> np.ndarray:
    """E(n)/pi of a radiance function f((S, 3) unit dirs) -> (S, C) at (..., 3) unit normals -> (..., C)."""
    local, weight = _hemisphere_rule(n_mu, n_phi)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    t, b = tangent_frames(nrm)
    out = []
    for k in range(nrm.shape[0]):
        dirs = to_world(local, t[k:k + 1], b[k:k + 1], nrm[k:k + 1])[0]
        out.append(weight @ np.asarray(radiance(dirs), np.float64) / np.pi)
    return np.stack(out).reshape(np.shape(normals)[:-1] + (out[0].shape[-1],))


def cube_from_function(radiance: Callable[[np.ndarray], np.ndarray], size: int) -> np.ndarray:
    """(6, size, size, C) cube sampled at texel centres from a radiance function of unit directions."""
    d = cubemap.face_directions(size)
    return np.asarray(radiance(d.reshape(-1, 3)), np.float64).reshape(6, size, size, -1)


def exact_ggx_prefilter(cube: np.ndarray, normals: np.ndarray, roughness: float) -> np.ndarray:
    """What the split-sum GGX estimator converges to, integrated over every texel (float64):

    prefiltered(n) = sum L(l) (n.l)+ D(n.h) dOmega / sum (n.l)+ D(n.h) dOmega,  h = normalize(n + l), V = N,
    because importance sampling with pdf(l) = D(h)/4 and weighting by n.l estimates exactly this ratio.
    """
    a2 = max(float(roughness), 1e-4) ** 4

    def kernel(n_dot_l: np.ndarray, dom: np.ndarray, lw: np.ndarray) -> np.ndarray:
        # n.h for h = normalize(n + l): |n + l| = sqrt(2 + 2 n.l), n.h = (1 + n.l) / |n + l| = sqrt((1 + n.l) / 2)
        n_dot_h2 = np.clip((1.0 + n_dot_l) * 0.5, 0.0, 1.0)
        d = a2 / (np.pi * (n_dot_h2 * (a2 - 1.0) + 1.0) ** 2)
        wt = np.maximum(n_dot_l, 0.0) * d * dom
        return (wt @ lw) / wt.sum(axis=1, keepdims=True)
    return _texel_sums(cube, normals, kernel)


# Synthetic environments with known character, for tests and demos. Each maps (S, 3) unit dirs -> (S, 3) RGB.

def smooth_environment(d: np.ndarray) -> np.ndarray:
    """A sky-like environment within SH band 2 in R and G (so order-2 SH irradiance is exact there) and a
    soft sun lobe exp(5 (x - 1)) in B (bands above 2 present but weak)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([0.5 + 0.3 * z + 0.8 * x * x, 1.0 + 0.2 * y * z, 0.2 + 0.1 * y + np.exp(5.0 * (x - 1.0))], -1)


def smooth_environment_irradiance(n: np.ndarray) -> np.ndarray:
    """Closed-form E/pi of smooth_environment's R and G channels (band <= 2: E/pi = sum (A_l/pi) L_l)."""
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    return np.stack([0.5 + 0.3 * (2.0 / 3.0) * z + 0.8 * (1.0 / 3.0 + 0.25 * (x * x - 1.0 / 3.0)),
                     1.0 + 0.2 * 0.25 * y * z], -1)


def bright_patch_environment(d: np.ndarray, centre=(0.3, 0.5, 0.81), radius_deg: float = 5.0,
                             bright: float = 1000.0, background: float = 0.1) -> np.ndarray:
    """A dim grey world with one small very bright disc (a sun/lamp seen by a probe): the hard case."""
    c = np.asarray(centre, np.float64)
    c = c / np.linalg.norm(c)
    v = np.where(d @ c > np.cos(np.radians(radius_deg)), bright, background)
    return np.stack([v, v, v], -1)
