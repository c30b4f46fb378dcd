"""A plain numpy splat renderer: the same maths as the GPU path, readable, for small scenes and tests.

No tiles: every live splat is tested against every ray, front to back in the GPU's depth order
(splat_math.sort_depths: distance from the origin, or depth along the view axis for one view), with the GPU's
rules (alpha clamp, nothing outside a splat's footprint, a ray finished once transmittance < 1e-4).

Two more for camera frames with meshes (SplatRenderer.render_camera): ``render_reference(cut=...)`` splits each
pixel's blend at a depth cut into FRONT and BEHIND layers by the GPU's rule, and ``render_reference_mesh`` is what
those layers stand for: each pixel's mesh sample inserted into the splats' front-to-back blend at its own depth.
"""
from __future__ import annotations

import numpy as np

from ..scene import SplatScene
from .splat_math import (ALPHA_MAX, DEFAULT_NEAR, T_MIN, PreparedSplats, batch_forward, depth_keys, prepare,
                         ray_mahalanobis, sort_depths)
from .views import ViewBatch


def _composite(p: PreparedSplats, order: np.ndarray, dirs: np.ndarray, chunk: int,
               cut: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per layer (colour (P, 3), transmittance (P,), zsum (P,)): zsum is the alpha-weighted sum of each
    contribution's closest approach along the ray, in units of the ray direction (view-space z for view rays).
    One layer; with ``cut`` (P,) two, FRONT (closest approach < cut) and BEHIND (the rest), each composited front to
    back among its own; the ray ends once FRONT is opaque, and BEHIND takes nothing more once what it lets through
    FRONT is below T_MIN."""
    n = len(dirs)
    layers = [(np.zeros((n, 3)), np.ones(n), np.zeros(n)) for _ in range(1 if cut is None else 2)]
    for start in range(0, len(order), chunk):
        idx = order[start:start + chunk]
        m, t, ahead = ray_mahalanobis(p, idx, dirs)
        alpha = np.minimum(ALPHA_MAX, p.opacity[idx, None] * np.exp(-0.5 * m))
        alpha = np.where(ahead & (m <= p.cutoff[idx, None]), alpha, 0.0)
        for k in range(len(idx)):  # compositing is sequential per splat; rays stay vectorised
            # a layer takes the splat while what it lets through is >= T_MIN (the splat crossing it counts): FRONT's
            # transmittance, BEHIND's times FRONT's
            t_front = layers[0][1]
            takes = [t_front >= T_MIN] + [t_front * tr >= T_MIN for _, tr, _ in layers[1:]]
            layer_of = np.zeros(n, int) if cut is None else (t[k] >= cut).astype(int)
            for i, (color, trans, zsum) in enumerate(layers):
                a = np.where(takes[i] & (layer_of == i), alpha[k], 0.0)
                color += (trans * a)[:, None] * p.color[idx[k]][None, :]
                zsum += trans * a * t[k]
                trans *= 1.0 - a
        if not (layers[0][1] >= T_MIN).any():
            break
    return layers


def _front_to_back(scene: SplatScene, origin, p: PreparedSplats, forward=None) -> np.ndarray:
    order = np.argsort(depth_keys(scene, origin, forward), kind="stable")
    return order[p.alive[order]]


def composite_rays(scene: SplatScene, origin, dirs: np.ndarray, dilation_angle: float = 0.0,
                   near: float = DEFAULT_NEAR, chunk: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Colour (M, 3) and alpha (M,) along rays from ``origin`` in directions (M, 3); dilation_angle 0: none."""
    p = prepare(scene, origin, dilation_angle, near)
    [(color, trans, _)] = _composite(p, _front_to_back(scene, origin, p),
                                     np.asarray(dirs, np.float64).reshape(-1, 3), chunk)
    return color, 1.0 - trans


def _per_view(batch: ViewBatch, x, channels: int = 1) -> list[np.ndarray]:
    """Per view, pixels x channels float64: ``x`` an array per view (one array for a one-view batch)."""
    xs = [x] if len(batch.views) == 1 and not isinstance(x, (list, tuple)) else list(x)
    return [np.asarray(a, np.float64).reshape(v.height * v.width, channels).squeeze(1 if channels == 1 else ())
            for v, a in zip(batch.views, xs, strict=True)]


def render_reference(scene: SplatScene, batch: ViewBatch, near: float = DEFAULT_NEAR, chunk: int = 64,
                     with_depth: bool = False, cut=None):
    """One (H, W, 4) float32 image per view: premultiplied linear RGB and alpha = 1 - transmittance; with_depth:
    also one (H, W) depth image per view (view-space z, coverage-weighted; 0 where nothing is seen).

    ``cut`` (per view an (H, W) distance along the view axis; one array for one view): the GPU's depth cut
    (SplatRenderer.render(cut=...)): returns (fronts, behinds[, depths]), the depth being FRONT over BEHIND's."""
    p = prepare(scene, batch.origin, batch.dilation, near, batch.energy_preserving)
    order = _front_to_back(scene, batch.origin, p, batch_forward(batch))
    cuts = _per_view(batch, cut) if cut is not None else [None] * len(batch.views)
    images, behinds, depths = [], [], []
    for view, c in zip(batch.views, cuts):
        layers = _composite(p, order, view.pixel_directions().reshape(-1, 3), chunk, c)
        rgba = [np.concatenate([col, 1.0 - tr[:, None]], 1).reshape(view.height, view.width, 4).astype(np.float32)
                for col, tr, _ in layers]
        images.append(rgba[0])
        behinds += rgba[1:]
        _, tt, z = layers[0]
        if c is not None:  # the depth of FRONT over BEHIND
            z, tt = z + tt * layers[1][2], tt * layers[1][1]
        depth = np.where(tt < 1, z / np.where(tt < 1, 1 - tt, 1), 0.0)
        depths.append(depth.reshape(view.height, view.width).astype(np.float32))
    out = (images, behinds) if cut is not None else (images,)
    out += (depths,) if with_depth else ()
    return out if len(out) > 1 else out[0]


def _composite_mesh(p: PreparedSplats, order: np.ndarray, dirs: np.ndarray, rgba: np.ndarray,
                    mesh_dist: np.ndarray, chunk: int, splat_dist: np.ndarray) -> np.ndarray:
    """(P, 4): the blend along rays (P, 3) of the splats in ``order`` and one mesh sample a ray (premultiplied
    ``rgba`` (P, 4) at sort depth ``mesh_dist`` (P,), +inf: none), each mesh sample after the splats whose sort
    depth ``splat_dist`` (N,) is nearer."""
    n = len(dirs)
    color, trans, placed = np.zeros((n, 3)), np.ones(n), ~np.isfinite(mesh_dist)

    def put_mesh(where):  # composite the mesh sample of the rays ``where``
        color[where] += trans[where, None] * rgba[where, :3]
        trans[where] *= 1.0 - rgba[where, 3]

    for start in range(0, len(order), chunk):
        idx = order[start:start + chunk]
        m, _, ahead = ray_mahalanobis(p, idx, dirs)
        alpha = np.minimum(ALPHA_MAX, p.opacity[idx, None] * np.exp(-0.5 * m))
        alpha = np.where(ahead & (m <= p.cutoff[idx, None]), alpha, 0.0)
        for k in range(len(idx)):
            now = ~placed & (mesh_dist <= splat_dist[idx[k]])
            put_mesh(now)
            placed |= now
            a = np.where(trans >= T_MIN, alpha[k], 0.0)
            color += (trans * a)[:, None] * p.color[idx[k]][None, :]
            trans *= 1.0 - a
        if not (trans >= T_MIN).any():
            break
    put_mesh(~placed)
    return np.concatenate([color, 1.0 - trans[:, None]], 1)


def render_reference_mesh(scene: SplatScene, batch: ViewBatch, mesh_rgba, mesh_depth, near: float = DEFAULT_NEAR,
                          chunk: int = 64) -> list[np.ndarray]:
    """What a mesh looks like standing in the splats, per view (H, W, 4) float32: each pixel's mesh sample
    (``mesh_rgba``: premultiplied (H, W, 4); ``mesh_depth``: (H, W) distance along the view axis, +inf where no
    mesh) inserted into the splats' front-to-back blend at its depth: the blend is ordered by the sort depth
    (splat_math.sort_depths): for one view the depth along its axis, and the mesh point, at mesh_depth, goes after
    every splat whose centre is nearer along that axis and before the rest; for several views the distance from the
    origin, the mesh point at mesh_depth |d| along the pixel's ray d. Several views take a list of each, as
    render_reference's ``cut``."""
    p = prepare(scene, batch.origin, batch.dilation, near, batch.energy_preserving)
    forward = batch_forward(batch)
    order = _front_to_back(scene, batch.origin, p, forward)
    splat_dist = sort_depths(scene, batch.origin, forward).astype(np.float64) if forward is not None else p.distance
    out = []
    for view, rgba, depth in zip(batch.views, _per_view(batch, mesh_rgba, 4), _per_view(batch, mesh_depth)):
        dirs = view.pixel_directions().reshape(-1, 3)
        mesh_dist = depth if forward is not None else depth * np.linalg.norm(dirs, axis=1)
        img = _composite_mesh(p, order, dirs, rgba, mesh_dist, chunk, splat_dist)
        out.append(img.reshape(view.height, view.width, 4).astype(np.float32))
    return out
