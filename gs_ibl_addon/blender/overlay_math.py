"""The viewport overlay's logic without bpy: viewport matrices -> a ViewBatch -> the splat image to draw.

Blender's 3D view gives ``region_3d.view_matrix`` (world -> view: x right, y up, looking down -z) and
``window_matrix`` (OpenGL projection). Our renderer takes a pinhole with a symmetric frustum and orthonormal axes,
so an off-centre projection (camera shift, a zoomed camera view) is rendered as the smallest symmetric frustum
that covers it, with the same pixel size, and drawn as a quad at the NDC rectangle where that frustum lands;
the GPU clips what lies outside the region. An orthographic view is approximated by a pinhole far behind the
view (ORTHO_DISTANCE times the view's half width: sizes at depth z shrink by about z / that distance).
The renderer's depth image (distance along the view axis) becomes the window depth Blender's depth buffer holds
(window_depth), so the draw handler can write it as fragment depth and meshes and splats occlude each other.
While a view keeps changing it is rendered at a lower resolution and refined once it has been still a moment
(ViewMotion). Everything here takes plain 4x4 numpy matrices, so it is tested without a window.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.colour import linear_to_srgb
from ..core.render.views import View, ViewBatch
from ..core.scene import SplatScene

ORTHO_DISTANCE = 100.0
MOVING_SCALE = 0.25  # resolution while the view moves: ~1/16 of the pixels
SETTLE_S = 0.25  # a view unchanged this long is still: rendered at the full Resolution setting
# Splats win depth ties within this fraction of their distance: a splat surface's depth is the mean over its
# blurry splats, and lines Blender draws on that surface (an object's bounds at the walls of a room) would show
# through it dashed; a mesh closer than 1 - DEPTH_PULL of the splat distance still hides the splats.
DEPTH_PULL = 0.02


@dataclass(frozen=True)
class OverlayView:
    batch: ViewBatch
    ndc_rect: tuple[float, float, float, float]  # (x0, y0, x1, y1): where the image's corners land, y up
    perspective: bool
    window_matrix: np.ndarray  # the viewport's projection (what window_depth maps depths through)
    depth_offset: float = 0.0  # how far the render origin sits behind the eye along the view axis (ortho only)


def _axes(view_matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(eye, right, down, forward) in world space from a world -> view matrix."""
    c = np.linalg.inv(np.asarray(view_matrix, np.float64))
    unit = [c[:3, k] / np.linalg.norm(c[:3, k]) for k in range(3)]
    return c[:3, 3].copy(), unit[0], -unit[1], -unit[2]


def _symmetric(lo: float, hi: float, pixels: float) -> tuple[float, int]:
    """Half extent and pixel count of the smallest symmetric interval covering [lo, hi] with the same pixel size."""
    px = (hi - lo) / pixels
    n = max(1, int(math.ceil(2.0 * max(abs(lo), abs(hi)) / px - 1e-6)))
    return 0.5 * n * px, n


def overlay_view(view_matrix, window_matrix, width: int, height: int, scale: float = 1.0) -> OverlayView:
    """The pinhole the overlay renders for a viewport region of ``width`` x ``height`` pixels.

    ``scale`` (0, 1] renders at that fraction of the region's resolution (the quad is stretched back over it).
    """
    v = np.asarray(view_matrix, np.float64)
    p = np.asarray(window_matrix, np.float64)
    if v.shape != (4, 4) or p.shape != (4, 4):
        raise ValueError(f"view and window matrices must be 4x4, got {v.shape} and {p.shape}")
    if width < 1 or height < 1 or not 0 < scale <= 1:
        raise ValueError(f"bad region size {width}x{height} or resolution scale {scale}")
    eye, right, down, forward = _axes(v)
    w_px, h_px = max(1.0, width * scale), max(1.0, height * scale)
    perspective = abs(p[3, 3]) < 1e-9
    if perspective:
        # ndc_x = P00 X - P02 for a point (X, Y, -1) of view space: the tangent plane at distance 1
        def tan_of(ndc, axis):
            return (ndc + p[axis, 2]) / p[axis, axis]
        shift = (p[0, 2], p[1, 2])
        origin = eye
        to_tan = 1.0
        dist = 0.0
    else:
        # ndc_x = P00 x + P03 for a point at view-space x: the view's half width in scene units at any depth
        def tan_of(ndc, axis):
            return (ndc - p[axis, 3]) / p[axis, axis]
        half = max(abs(tan_of(-1, 0)), abs(tan_of(1, 0)), abs(tan_of(-1, 1)), abs(tan_of(1, 1)))
        dist = ORTHO_DISTANCE * half
        origin = eye - dist * forward
        to_tan = 1.0 / dist
        shift = (-p[0, 3], -p[1, 3])
    (l, r), (b, t) = [(tan_of(-1.0, a) * to_tan, tan_of(1.0, a) * to_tan) for a in (0, 1)]
    tan_x, nx = _symmetric(l, r, w_px)
    tan_y, ny = _symmetric(b, t, h_px)
    view = View(forward, right, down, tan_x, tan_y, nx, ny)
    batch = ViewBatch(np.asarray(origin, np.float64), (view,), 2.0 * tan_x / nx)
    # Where +-tan lands in NDC: the inverse of tan_of.
    sx, sy = p[0, 0] / to_tan, p[1, 1] / to_tan
    rect = (-sx * tan_x - shift[0], -sy * tan_y - shift[1], sx * tan_x - shift[0], sy * tan_y - shift[1])
    return OverlayView(batch, tuple(float(x) for x in rect), perspective, p.copy(), float(dist))


def window_depth(depth: np.ndarray, view: OverlayView, pull: float = 0.0) -> np.ndarray:
    """The renderer's depth image -> the window depth [0, 1] the viewport's depth buffer holds for those points.

    ``depth`` is the distance along the render camera's view axis (RenderResult.depths; 0 where no splat is seen).
    That camera looks along the viewport's -z from ``depth_offset`` behind the eye, so view-space z is
    -(depth - offset); through the window matrix: ndc_z = (P22 z + P23) / (P32 z + P33) (perspective: w = -z,
    orthographic: w = 1), window = (ndc_z + 1) / 2, OpenGL's default depth range, which Blender uses in every
    backend. Pixels without splats, and points outside the near/far planes, get 1 (the far plane; the draw
    discards them, or clipping would have). ``pull`` moves every depth that fraction of its distance closer.
    """
    d = np.asarray(depth, np.float64)
    p = view.window_matrix
    z = -(d - view.depth_offset) * (1.0 - pull)
    w = p[3, 2] * z + p[3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = (p[2, 2] * z + p[2, 3]) / w
    win = 0.5 * ndc + 0.5
    inside = (d > 0) & (w > 0) & (win >= 0.0) & (win <= 1.0)
    return np.where(inside, win, 1.0).astype(np.float32)


def view_key(view_matrix, window_matrix, width: int, height: int) -> bytes:
    """What a viewport's image depends on besides the splats and the resolution."""
    return (np.asarray(view_matrix, np.float64).tobytes() + np.asarray(window_matrix, np.float64).tobytes()
            + np.array([width, height], np.float64).tobytes())


class ViewMotion:
    """Per viewport region: render at MOVING_SCALE while its view changes, at the full setting once still.

    ``scale`` is called at every draw with the clock. A view that changed within the last SETTLE_S seconds is
    moving (a drag redraws it every frame: coarse frames keep it responsive); a region seen for the first time is
    drawn at full resolution at once. ``refine_in`` says when a region drawn coarse will have been still long
    enough for its full-resolution image: the handler schedules one redraw then.
    """

    def __init__(self, settle_s: float = SETTLE_S, moving_scale: float = MOVING_SCALE) -> None:
        self.settle_s, self.moving_scale = settle_s, moving_scale
        self._slots: dict[object, list] = {}  # slot -> [key, time of its last change, last drawn coarse]

    def scale(self, slot: object, key: bytes, now: float, full_scale: float) -> float:
        st = self._slots.get(slot)
        if st is None:
            self._slots[slot] = [key, -math.inf, False]
            return full_scale
        if st[0] != key:
            st[0], st[1] = key, now
        st[2] = now - st[1] < self.settle_s and self.moving_scale < full_scale
        return self.moving_scale if st[2] else full_scale

    def refine_in(self, now: float) -> float | None:
        """Seconds until the earliest coarse region settles (0 if one already has), None when none is coarse."""
        waits = [max(0.0, st[1] + self.settle_s - now) for st in self._slots.values() if st[2]]
        return min(waits) if waits else None


def to_display(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Premultiplied linear RGBA -> premultiplied RGBA with sRGB-encoded colour, clipped to [0, 1].

    The viewport's image shader decodes sRGB to the framebuffer's linear space, so premultiplied blending there
    composites the splats' linear light over the scene; colours above 1 clip (no view transform is applied).
    """
    img = np.asarray(image, np.float32)
    a = img[..., 3:4]
    rgb = img[..., :3] * np.float32(2.0 ** exposure)
    colour = np.where(a > 1e-6, rgb / np.maximum(a, 1e-6), 0.0)
    out = np.empty_like(img)
    out[..., :3] = linear_to_srgb(np.clip(colour, 0.0, 1.0) * a)
    out[..., 3:] = np.clip(a, 0.0, 1.0)
    return out


@dataclass
class OverlayImage:
    rgba: np.ndarray  # (H, W, 4) premultiplied linear RGBA, row 0 at the top
    view: OverlayView
    render_ms: float
    depth: np.ndarray | None = None  # (H, W) distance along the view axis (0: no splat), rows as rgba
    scale: float = 1.0

    def window_depth(self, pull: float = 0.0) -> np.ndarray:
        return window_depth(self.depth, self.view, pull)


class SplatOverlay:
    """One splat object's GPU renderer (scene uploaded once) and its last image per viewport.

    ``image`` re-renders only when the matrices, the region size or the scale changed; ``renders`` counts renders.
    A renderer passed in stays its owner's (close() leaves it open); one made here is closed with the overlay.
    """

    def __init__(self, scene: SplatScene | None = None, renderer=None) -> None:
        if scene is None and renderer is None:
            raise ValueError("SplatOverlay needs splats: a scene to upload or a renderer holding them")
        self._owns_renderer = renderer is None
        if renderer is None:
            from ..core.render.renderer import SplatRenderer
            renderer = SplatRenderer(scene)
        self.renderer = renderer
        self.renders = 0
        self._last: dict[object, tuple[bytes, OverlayImage]] = {}

    def image(self, view_matrix, window_matrix, width: int, height: int, scale: float = 1.0,
              slot: object = 0) -> OverlayImage:
        key = view_key(view_matrix, window_matrix, width, height) + np.float64(scale).tobytes()
        last = self._last.get(slot)
        if last is not None and last[0] == key:
            return last[1]
        ov = overlay_view(view_matrix, window_matrix, width, height, scale)
        res = self.renderer.render(ov.batch, depth=True)  # the overlay hides splats behind meshes by depth
        self.renders += 1
        img = OverlayImage(res.images[0], ov, res.wall_ms, res.depths[0], scale)
        self._last[slot] = (key, img)
        return img

    def close(self) -> None:
        self._last.clear()
        if self._owns_renderer:
            self.renderer.close()


def perspective_matrix(fov_x_deg: float, width: int, height: int, near: float = 0.1, far: float = 100.0,
                       shift_x: float = 0.0, shift_y: float = 0.0) -> np.ndarray:
    """An OpenGL projection like Blender's window_matrix: horizontal field of view, optional shift (in units of
    the larger image side, as Blender's camera shift)."""
    tx = math.tan(math.radians(fov_x_deg) / 2.0)
    ty = tx * height / width
    span = 2.0 * max(tx, ty)
    cx, cy = shift_x * span, shift_y * span
    l, r, b, t = -tx + cx, tx + cx, -ty + cy, ty + cy
    m = np.zeros((4, 4))
    m[0, 0], m[0, 2] = 2.0 / (r - l), (r + l) / (r - l)
    m[1, 1], m[1, 2] = 2.0 / (t - b), (t + b) / (t - b)
    m[2, 2], m[2, 3] = -(far + near) / (far - near), -2.0 * far * near / (far - near)
    m[3, 2] = -1.0
    return m


def look_at_view_matrix(position, look_at, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World -> view matrix (x right, y up, looking down -z) of a camera at ``position`` looking at ``look_at``."""
    o = np.asarray(position, np.float64)
    f = np.asarray(look_at, np.float64) - o
    f /= np.linalg.norm(f)
    r = np.cross(f, np.asarray(up, np.float64))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    c = np.identity(4)
    c[:3, 0], c[:3, 1], c[:3, 2], c[:3, 3] = r, u, -f, o
    return np.linalg.inv(c)
