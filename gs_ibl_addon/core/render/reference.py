"""A plain numpy splat renderer: the same maths as the GPU path, readable, for small scenes and tests.

No tiles: every live splat is tested against every ray, front to back by distance from the origin, with the
GPU's rules (alpha clamp, nothing outside a splat's footprint, a ray finished once transmittance < 1e-4).
"""
from __future__ import annotations

import numpy as np

from ..scene import SplatScene
from .splat_math import ALPHA_MAX, DEFAULT_NEAR, T_MIN, PreparedSplats, depth_keys, prepare, ray_mahalanobis
from .views import ViewBatch


def _composite(p: PreparedSplats, order: np.ndarray, dirs: np.ndarray,
               chunk: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(colour (P, 3), alpha (P,), depth (P,)): depth is the alpha-weighted mean of each contribution's closest
    approach along the ray, in units of the ray direction (view-space z for view rays), 0 where nothing is seen."""
    n = len(dirs)
    color = np.zeros((n, 3))
    trans = np.ones(n)
    zsum = np.zeros(n)
    done = np.zeros(n, bool)
    for start in range(0, len(order), chunk):
        idx = order[start:start + chunk]
        m, t, ahead = ray_mahalanobis(p, idx, dirs)
        alpha = np.minimum(ALPHA_MAX, p.opacity[idx, None] * np.exp(-0.5 * m))
        alpha = np.where(ahead & (m <= p.cutoff[idx, None]), alpha, 0.0)
        for k in range(len(idx)):  # compositing is sequential per splat; rays stay vectorised
            a = np.where(done, 0.0, alpha[k])
            color += (trans * a)[:, None] * p.color[idx[k]][None, :]
            zsum += trans * a * t[k]
            trans = trans * (1.0 - a)
            done |= trans < T_MIN  # the splat crossing T_MIN counts, then the ray is finished
        if done.all():
            break
    alpha = 1.0 - trans
    return color, alpha, np.where(alpha > 0, zsum / np.where(alpha > 0, alpha, 1.0), 0.0)


def _front_to_back(scene: SplatScene, origin, p: PreparedSplats) -> np.ndarray:
    order = np.argsort(depth_keys(scene, origin), kind="stable")
    return order[p.alive[order]]


def composite_rays(scene: SplatScene, origin, dirs: np.ndarray, dilation_angle: float = 0.0,
                   near: float = DEFAULT_NEAR, chunk: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Colour (M, 3) and alpha (M,) along rays from ``origin`` in directions (M, 3); dilation_angle 0: none."""
    p = prepare(scene, origin, dilation_angle, near)
    color, alpha, _ = _composite(p, _front_to_back(scene, origin, p), np.asarray(dirs, np.float64).reshape(-1, 3),
                                 chunk)
    return color, alpha


def render_reference(scene: SplatScene, batch: ViewBatch, near: float = DEFAULT_NEAR, chunk: int = 64,
                     with_depth: bool = False) -> list[np.ndarray] | tuple[list[np.ndarray], list[np.ndarray]]:
    """One (H, W, 4) float32 image per view: premultiplied linear RGB and alpha = 1 - transmittance; with_depth:
    also one (H, W) depth image per view (view-space z, coverage-weighted; 0 where nothing is seen)."""
    p = prepare(scene, batch.origin, batch.dilation, near, batch.energy_preserving)
    order = _front_to_back(scene, batch.origin, p)
    images, depths = [], []
    for view in batch.views:
        color, alpha, depth = _composite(p, order, view.pixel_directions().reshape(-1, 3), chunk)
        img = np.concatenate([color, alpha[:, None]], 1).reshape(view.height, view.width, 4)
        images.append(img.astype(np.float32))
        depths.append(depth.reshape(view.height, view.width).astype(np.float32))
    return (images, depths) if with_depth else images
