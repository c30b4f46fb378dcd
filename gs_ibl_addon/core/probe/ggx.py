"""GGX prefiltered radiance for glossy reflections (split-sum, Karis 2013), one cube per roughness level.

Per output direction R, with the split-sum assumption N = V = R, half-vectors are importance sampled from
the GGX distribution (alpha = roughness^2) on a Hammersley sequence, reflected to light directions L, and
    prefiltered(R) = sum L_in(L) (N.L) / sum (N.L)   over samples with N.L > 0.
Fireflies from a few samples landing on a small bright source are removed by filtered importance sampling
(Colbert & Krivanek, GPU Gems 3 ch. 20): each sample reads the radiance mip whose texel solid angle matches
the sample's share of the lobe, lod = 0.5 log2(Omega_s / Omega_p) + bias, Omega_s = 1 / (S pdf),
Omega_p = 4 pi / (6 N^2), pdf(L) = D(h) / 4 (because N = V). Mips come from box.mip_chain (solid-angle weighted).
"""
from __future__ import annotations

import numpy as np

from .. import cubemap
from .box import mip_chain
from .reference import row_chunks, tangent_frames, to_world
from .sampling import check_cube, sample_mips_trilinear

DEFAULT_ROUGHNESS = (0.0, 0.25, 0.5, 0.75, 1.0)
_CHUNK_SAMPLES = 1 << 20


def hammersley(count: int) -> np.ndarray:
    """(count, 2) points of the Hammersley set (i/count, radical inverse base 2 of i)."""
    i = np.arange(count, dtype=np.uint32)
    bits = i.copy()
    bits = ((bits << 16) | (bits >> 16)) & 0xFFFFFFFF
    bits = ((bits & 0x55555555) << 1) | ((bits & 0xAAAAAAAA) >> 1)
    bits = ((bits & 0x33333333) << 2) | ((bits & 0xCCCCCCCC) >> 2)
    bits = ((bits & 0x0F0F0F0F) << 4) | ((bits & 0xF0F0F0F0) >> 4)
    bits = ((bits & 0x00FF00FF) << 8) | ((bits & 0xFF00FF00) >> 8)
    return np.stack([i / count, bits.astype(np.float64) / 2.0 ** 32], -1)


def ggx_samples(roughness: float, count: int, base_size: int, lod_bias: float = 1.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local light directions (S, 3) about +Z, weights N.L (S,) and mip lods (S,), samples with N.L <= 0 dropped."""
    alpha = max(float(roughness), 1e-4) ** 2
    xi = hammersley(count)
    phi = 2.0 * np.pi * xi[:, 0]
    cos_h = np.sqrt((1.0 - xi[:, 1]) / (1.0 + (alpha * alpha - 1.0) * xi[:, 1]))
    sin_h = np.sqrt(np.maximum(0.0, 1.0 - cos_h * cos_h))
    h = np.stack([sin_h * np.cos(phi), sin_h * np.sin(phi), cos_h], -1)
    light = 2.0 * cos_h[:, None] * h - np.array([0.0, 0.0, 1.0])  # reflect V = N = +Z about h
    n_dot_l = light[:, 2]
    d = alpha * alpha / (np.pi * (cos_h * cos_h * (alpha * alpha - 1.0) + 1.0) ** 2)
    omega_s = 1.0 / (count * d / 4.0)
    omega_p = 4.0 * np.pi / (6.0 * base_size * base_size)
    lod = np.maximum(0.5 * np.log2(omega_s / omega_p) + lod_bias, 0.0)
    keep = n_dot_l > 0.0
    return light[keep], n_dot_l[keep], lod[keep]


def ggx_prefilter_level(mips: list[np.ndarray], size: int, roughness: float, samples: int = 256,
                        lod_bias: float = 1.0) -> np.ndarray:
    """One prefiltered cube (6, size, size, C) for one roughness from a radiance mip chain."""
    normals = cubemap.face_directions(size).reshape(-1, 3)
    base = mips[0].shape[1]
    if roughness <= 0.0:
        # A mirror: the radiance itself, read from the mip whose texels match the output's (no aliasing).
        lod = np.full(normals.shape[0], max(0.0, np.log2(base / size)))
        return sample_mips_trilinear(mips, normals, lod).reshape(6, size, size, -1)
    local, w, lod = ggx_samples(roughness, samples, base, lod_bias)
    t, b = tangent_frames(normals)
    out = np.empty((normals.shape[0], mips[0].shape[3]))
    for sl in row_chunks(normals.shape[0], len(w), _CHUNK_SAMPLES):
        dirs = to_world(local, t[sl], b[sl], normals[sl])
        vals = sample_mips_trilinear(mips, dirs, np.broadcast_to(lod, dirs.shape[:2]))
        out[sl] = np.einsum("s,msc->mc", w, vals) / w.sum()
    return out.reshape(6, size, size, -1)


def level_sizes(face_size: int, roughness: tuple[float, ...], sizes: tuple[int, ...] | None, samples: int
                ) -> tuple[int, ...]:
    """Output face size per roughness level (default: the face size halved per level, >= 4), checked along with
    the sample count (numpy and GPU prefilters alike)."""
    if sizes is None:
        sizes = tuple(max(4, face_size >> k) for k in range(len(roughness)))
    if len(sizes) != len(roughness):
        raise ValueError(f"GGX prefilter: {len(roughness)} roughness levels but {len(sizes)} sizes")
    if roughness and (samples < 1 or min(sizes) < 1):
        raise ValueError(f"GGX prefilter: needs samples >= 1 and face sizes >= 1, got {samples} and {sizes}")
    return tuple(int(m) for m in sizes)


def ggx_prefilter(cube: np.ndarray, roughness: tuple[float, ...] = DEFAULT_ROUGHNESS,
                  sizes: tuple[int, ...] | None = None, samples: int = 256, lod_bias: float = 1.0
                  ) -> list[np.ndarray]:
    """Radiance cube -> one prefiltered cube per roughness (default sizes: face size halved per level, >= 4)."""
    a = check_cube(cube)
    sizes = level_sizes(a.shape[1], roughness, sizes, samples)
    mips = mip_chain(a)
    return [ggx_prefilter_level(mips, s, r, samples, lod_bias) for r, s in zip(roughness, sizes)]
