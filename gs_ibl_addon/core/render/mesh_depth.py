"""The depth of meshes seen by a camera, per pixel, in numpy: where a final render splits the splats into the part in
front of the meshes and the part behind them (docs/final-frame.md, design A).

The camera is Blender's pinhole as ``ViewBatch.camera`` describes it (core/render/views.py): a camera-to-world
matrix looking down its local -Z (+Y up, +X right; scale taken out), the tangents of the frame's half angles
(``tan_x``, ``tan_y``) and the centre offset of a lens shift (``cx`` right, ``cy`` up, at distance 1), over a
``width`` x ``height`` pixel grid, of which a ``window`` (x0, y0, x1, y1; rows from the top) may be asked for.
Pixel (i, j), row j from the top, looks along forward + (s tan_x + cx) right + (t tan_y - cy) down with s, t its
centre in (-1, 1). Depth is the planar distance along the view axis (what Cycles' Depth pass holds and what the
renderer's depth cut takes), +inf where no mesh is seen. Images are rows top first, like the renderer's.

``rasterise`` is a scanline rasteriser vectorised over (triangle, row) spans: no Python loop over triangles; the
pixel work goes in chunks of at most ``CHUNK`` (pixel, triangle) pairs, so a frame-filling triangle costs its pixels
and no more. Triangles are clipped at the near plane (one behind it gives two, two give one) and depths beyond the
far plane are dropped, as the engines clip them. ``fill_edges`` is the prototype's edge fix: an anti-aliased mesh
edge spreads its colour into pixels whose centre misses the mesh, so an empty pixel takes the depth of a covered
4-neighbour (the nearest of them), else of a covered diagonal one.

``rasterise_ortho`` is the same scanline for an orthographic view (depth affine in screen space, not its inverse):
the shadow maps of core/render/shadows.py.
"""
from __future__ import annotations

import numpy as np

FAR = np.inf
CHUNK = 1 << 21  # (pixel, triangle) pairs evaluated at once: ~100 MB of temporaries


def camera_basis(cam_to_world) -> np.ndarray:
    """The camera's 4x4 camera-to-world matrix with scale and shear taken out (orthonormal, right-handed), made the
    way ViewBatch.camera makes its view: forward = -Z, right = X made orthogonal to it, up = forward x right."""
    m = np.asarray(cam_to_world, np.float64)
    f = -m[:3, 2] / np.linalg.norm(m[:3, 2])
    r = m[:3, 0] - (m[:3, 0] @ f) * f
    r /= np.linalg.norm(r)
    up = np.cross(-f, r)  # Y = Z x X with Z = -f
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = r, up, -f, m[:3, 3]
    return out


def frustum_from_projection(proj) -> tuple[float, float, float, float]:
    """(tan_x, tan_y, cx, cy) of an OpenGL perspective projection matrix (Blender's calc_matrix_camera: sensor fit,
    pixel aspect and lens shift included). ValueError for an orthographic one."""
    p = np.asarray(proj, np.float64)
    if abs(p[3, 3]) > 1e-12 or abs(p[3, 2] + 1.0) > 1e-6:
        raise ValueError("not a perspective projection (an orthographic camera)")
    return 1.0 / p[0, 0], 1.0 / p[1, 1], p[0, 2] / p[0, 0], p[1, 2] / p[1, 1]


def _clip_near(cam: np.ndarray, near: float) -> np.ndarray:
    """Camera-space triangles (m, 3, 3) clipped to depth (-z) >= near: triangles wholly behind it go, one vertex
    behind gives two triangles, two behind give one."""
    d = -cam[..., 2]
    behind = d < near
    nb = behind.sum(1)
    keep = [cam[nb == 0]]
    for count, odd in ((1, True), (2, False)):
        sel = nb == count
        if not sel.any():
            continue
        t, b = cam[sel], behind[sel]
        first = np.argmax(b == odd, axis=1)  # the vertex on its own side goes first; the cyclic order is kept
        order = (first[:, None] + np.arange(3)) % 3
        t = np.take_along_axis(t, order[..., None], 1)
        a, p, q = t[:, 0], t[:, 1], t[:, 2]
        da, dp, dq = -a[:, 2:3], -p[:, 2:3], -q[:, 2:3]
        ap = a + (p - a) * ((near - da) / (dp - da))  # where the edges cross the near plane
        aq = a + (q - a) * ((near - da) / (dq - da))
        if odd:  # a behind: the quad ap, p, q, aq
            keep += [np.stack([ap, p, q], 1), np.stack([ap, q, aq], 1)]
        else:  # p and q behind: a, ap, aq
            keep.append(np.stack([a, ap, aq], 1))
    return np.concatenate(keep) if keep else np.zeros((0, 3, 3))


def rasterise(triangles, cam_to_world, tan_x: float, tan_y: float, width: int, height: int, cx: float = 0.0,
              cy: float = 0.0, window=None, near: float = 1e-3, far: float = np.inf) -> np.ndarray:
    """Planar depth (H, W) float32 of the nearest of ``triangles`` (m, 3, 3) world-space vertices at each pixel
    centre of the camera's ``window`` (default the whole width x height frame), +inf where none; rows top first."""
    x0, y0, x1, y1 = (0, 0, int(width), int(height)) if window is None else (int(v) for v in window)
    ww, wh = x1 - x0, y1 - y0
    zbuf = np.full(ww * wh, np.inf, np.float64)
    tri = np.asarray(triangles, np.float64).reshape(-1, 3, 3)
    if len(tri) and ww > 0 and wh > 0:
        c2w = camera_basis(cam_to_world)
        cam = (tri - c2w[:3, 3]) @ c2w[:3, :3]  # world -> camera: R^T (p - o)
        cam = _clip_near(cam[np.isfinite(cam).all((1, 2))], near)
        d = -cam[..., 2]
        # continuous pixel coordinates (a pixel's centre at i + 0.5) of the frame, then of the window
        px = ((cam[..., 0] / d - cx) / tan_x + 1.0) * 0.5 * width - x0
        py = ((-cam[..., 1] / d + cy) / tan_y + 1.0) * 0.5 * height - y0
        _scan(px, py, 1.0 / d, ww, wh, zbuf)
    z = zbuf.reshape(wh, ww)
    z[z > far] = np.inf
    return z.astype(np.float32)


def _scan(px: np.ndarray, py: np.ndarray, inv_d: np.ndarray, ww: int, wh: int, zbuf: np.ndarray,
          reciprocal: bool = True) -> None:
    """Min-depth of screen-space triangles (vertices px, py: (m, 3), 1/depth inv_d: (m, 3)) into zbuf (wh * ww).
    reciprocal=False: ``inv_d`` is the depth itself, affine in screen space (an orthographic view)."""
    # edge functions e_k(x, y) = A_k x + B_k y + C_k, >= 0 inside for a triangle of either winding
    xa, xb = px, np.roll(px, -1, 1)
    ya, yb = py, np.roll(py, -1, 1)
    A, B = ya - yb, xb - xa
    C = xa * yb - xb * ya
    area = C.sum(1)  # twice the signed area
    ok = np.abs(area) > 1e-12
    sign = np.sign(area)[:, None]
    A, B, C = A * sign, B * sign, C * sign
    # 1/depth is affine in screen space: inv_d = alpha x + beta y + gamma (barycentric weights e_k / area)
    w_next = np.roll(inv_d, -2, 1)  # e_k is 0 on edge k (vertices k, k+1): it weighs the opposite vertex k+2
    den = np.abs(area)
    alpha = (A * w_next).sum(1) / np.where(ok, den, 1)
    beta = (B * w_next).sum(1) / np.where(ok, den, 1)
    gamma = (C * w_next).sum(1) / np.where(ok, den, 1)
    r0 = np.maximum(np.ceil(py.min(1) - 0.5), 0).astype(np.int64)
    r1 = np.minimum(np.floor(py.max(1) - 0.5), wh - 1).astype(np.int64)
    lo_x = np.maximum(np.ceil(px.min(1) - 0.5), 0)
    hi_x = np.minimum(np.floor(px.max(1) - 0.5), ww - 1)
    ok &= (r1 >= r0) & (hi_x >= lo_x) & np.isfinite(alpha + beta + gamma)
    idx = np.nonzero(ok)[0]
    if not len(idx):
        return
    rows = (r1 - r0 + 1)[idx]
    # (triangle, row) spans
    t = np.repeat(idx, rows)
    row = r0[t] + (np.arange(len(t)) - np.repeat(np.cumsum(rows) - rows, rows))
    y = row + 0.5
    eps = 1e-9 * np.abs(np.where(ok, area, 1))[t]  # shared edges belong to both triangles (the min decides)
    xl, xr = lo_x[t] + 0.5, hi_x[t] + 0.5
    for k in range(3):  # A x + (B y + C) >= 0 bounds x on one side
        a, rest = A[t, k], B[t, k] * y + C[t, k] + eps
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = -rest / a
        xl = np.where(a > 0, np.maximum(xl, bound), xl)
        xr = np.where(a < 0, np.minimum(xr, bound), xr)
        xr = np.where((a == 0) & (rest < 0), -np.inf, xr)  # a horizontal edge whose outside this row is
    c0 = np.ceil(np.clip(xl, -1.0, ww + 1.0) - 0.5).astype(np.int64)
    c1 = np.floor(np.clip(xr, -1.0, ww + 1.0) - 0.5).astype(np.int64)
    n = np.maximum(c1 - c0 + 1, 0)
    keep = n > 0
    t, row, c0, n = t[keep], row[keep], c0[keep], n[keep]
    ends = np.cumsum(n)
    start = 0
    while start < len(n):  # spans in chunks of about CHUNK pixels (one span is at most a row)
        stop = int(np.searchsorted(ends, (ends[start - 1] if start else 0) + CHUNK, "right"))
        stop = max(stop, start + 1)
        ns = n[start:stop]
        first = np.cumsum(ns) - ns
        span = np.repeat(np.arange(start, stop), ns)
        col = c0[span] + (np.arange(int(ns.sum())) - np.repeat(first, ns))
        tt = t[span]
        inv = alpha[tt] * (col + 0.5) + beta[tt] * (row[span] + 0.5) + gamma[tt]
        depth = 1.0 / np.maximum(inv, 1e-300) if reciprocal else inv
        np.minimum.at(zbuf, row[span] * ww + col, depth)
        start = stop


def rasterise_ortho(triangles, basis, extent, width: int, height: int) -> np.ndarray:
    """Depth (H, W) float32 of the nearest of ``triangles`` (m, 3, 3) world-space vertices seen by an orthographic
    view, +inf where none; rows top first. ``basis``: (3, 3) rows right, up, forward (orthonormal); depth is
    p . forward (any sign: nothing is clipped); ``extent`` (u0, v0, u1, v1): the view's rectangle in (p . right,
    p . up), column i's centre at u0 + (i + 0.5) (u1 - u0) / W, row j's at v1 - (j + 0.5) (v1 - v0) / H. A light's
    shadow map (core/render/shadows.py)."""
    zbuf = np.full(int(width) * int(height), np.inf, np.float64)
    tri = np.asarray(triangles, np.float64).reshape(-1, 3, 3)
    tri = tri[np.isfinite(tri).all((1, 2))]
    if len(tri) and width > 0 and height > 0:
        b = np.asarray(basis, np.float64)
        u0, v0, u1, v1 = (float(e) for e in extent)
        p = tri @ b.T  # (m, 3, 3): right, up, forward coordinates
        px = (p[..., 0] - u0) * (width / (u1 - u0))
        py = (v1 - p[..., 1]) * (height / (v1 - v0))
        _scan(px, py, p[..., 2], int(width), int(height), zbuf, reciprocal=False)
    return zbuf.reshape(int(height), int(width)).astype(np.float32)


def fill_edges(z: np.ndarray) -> np.ndarray:
    """Every empty pixel (+inf) next to a covered one takes that neighbour's depth: a covered 4-neighbour first (the
    nearest of them), else a covered diagonal one. Pixels no mesh reaches stay +inf (the split changes nothing
    there)."""
    z = np.asarray(z)
    h, w = z.shape
    p = np.pad(z, 1, constant_values=np.inf)

    def nearest(offsets):
        return np.min([p[1 + dy:h + 1 + dy, 1 + dx:w + 1 + dx] for dy, dx in offsets], axis=0)
    four = nearest(((-1, 0), (1, 0), (0, -1), (0, 1)))
    diag = nearest(((-1, -1), (-1, 1), (1, -1), (1, 1)))
    return np.where(np.isfinite(z), z, np.where(np.isfinite(four), four, diag))


def mesh_depth(triangles, cam_to_world, tan_x: float, tan_y: float, width: int, height: int, cx: float = 0.0,
               cy: float = 0.0, window=None, near: float = 1e-3, far: float = np.inf) -> np.ndarray:
    """The depth a final render splits the splats at: ``rasterise`` with ``fill_edges``, the window rasterised one
    pixel wider on each side so that its border pixels see the meshes just outside it."""
    x0, y0, x1, y1 = (0, 0, int(width), int(height)) if window is None else (int(v) for v in window)
    ex0, ey0, ex1, ey1 = max(x0 - 1, 0), max(y0 - 1, 0), min(x1 + 1, width), min(y1 + 1, height)
    z = fill_edges(rasterise(triangles, cam_to_world, tan_x, tan_y, width, height, cx, cy, (ex0, ey0, ex1, ey1),
                             near, far))
    return z[y0 - ey0:y0 - ey0 + (y1 - y0), x0 - ex0:x0 - ex0 + (x1 - x0)]
