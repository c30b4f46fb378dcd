"""A plain numpy splat renderer: the same maths as the GPU path, readable, for small scenes and tests.

No tiles: every live splat is tested against every pixel, front to back by distance from the origin, with the
GPU's rules (alpha clamp, nothing outside a splat's footprint, a pixel finished once transmittance < 1e-4).
"""
from __future__ import annotations

import numpy as np

from ..scene import SplatScene
from .splat_math import ALPHA_MAX, DEFAULT_NEAR, T_MIN, depth_keys, prepare, ray_mahalanobis
from .views import ViewBatch


def render_reference(scene: SplatScene, batch: ViewBatch, near: float = DEFAULT_NEAR, chunk: int = 64) -> list[np.ndarray]:
    """One (H, W, 4) float32 image per view: premultiplied linear RGB and alpha = 1 - transmittance."""
    p = prepare(scene, batch.origin, batch.pixel_angle, near, batch.energy_preserving)
    order = np.argsort(depth_keys(scene, batch.origin), kind="stable")
    order = order[p.alive[order]]
    images = []
    for view in batch.views:
        dirs = view.pixel_directions().reshape(-1, 3)
        npx = len(dirs)
        color = np.zeros((npx, 3))
        trans = np.ones(npx)
        done = np.zeros(npx, bool)
        for start in range(0, len(order), chunk):
            idx = order[start:start + chunk]
            m, ahead = ray_mahalanobis(p, idx, dirs)
            alpha = np.minimum(ALPHA_MAX, p.opacity[idx, None] * np.exp(-0.5 * m))
            alpha = np.where(ahead & (m <= p.cutoff[idx, None]), alpha, 0.0)
            for k in range(len(idx)):  # compositing is sequential per splat; pixels stay vectorised
                a = np.where(done, 0.0, alpha[k])
                color += (trans * a)[:, None] * p.color[idx[k]][None, :]
                trans = trans * (1.0 - a)
                done |= trans < T_MIN  # the splat crossing T_MIN counts, then the pixel is finished
            if done.all():
                break
        img = np.concatenate([color, (1.0 - trans)[:, None]], 1).reshape(view.height, view.width, 4)
        images.append(img.astype(np.float32))
    return images
