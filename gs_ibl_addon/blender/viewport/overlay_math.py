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

The draw handler composites the splats into Blender's overlay layer in one pass of its own shader (composite is
that shader's numpy reference, see its docstring): it reads what Blender drew there and the scene depth, so mesh
silhouettes keep their anti-aliasing against the splats, the floor grid never shows through them, and the 3D cursor
and object origins stay on top. The viewport operators that put the 3D cursor on the splats and select splat
objects by clicking them find the splats under the mouse in the last image drawn (mouse_ray, splat_hit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.colour import linear_to_srgb, srgb_to_linear
from ...core.render.views import View, ViewBatch
from ...core.scene import SplatScene

ORTHO_DISTANCE = 100.0
MOVING_SCALE = 0.25  # resolution while the view moves: ~1/16 of the pixels
SETTLE_S = 0.25  # a view unchanged this long is still: rendered at the full Resolution setting
# Moving frames of a scene above MOTION_BUDGET splats draw a coarse copy of that many (SplatOverlay) where the full
# scene's last render took over MOTION_FRAME_MS: on lavapipe (2 cores, load ~3.5) a 3M-splat orbit went from 0.15
# to ~9 frames/s at 1311x878, core only (docs/benchmarks.md, "Overlay while the view moves"); a GPU that draws the
# full scene within a 60 Hz frame keeps full detail.
MOTION_BUDGET = 100_000
MOTION_FRAME_MS = 1000.0 / 60.0
# The copy is drawn at this fraction of MOVING_SCALE: its cells are wider than a pixel there already, so halving the
# resolution again measured no added error and halves the raster and tile sort (docs/benchmarks.md)
MOTION_RESOLUTION = 0.5
MOTION_LOD_K = 2.0  # the copy's own octree cut, in rendered pixels: far parts of a scene seen whole merge further
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
    drawn at full resolution at once. ``moving`` tells the draw whether that region is moving (SplatOverlay.image
    then draws a big scene's coarse copy), also where the Resolution setting is already below MOVING_SCALE.
    ``refine_in`` says when a region drawn while moving will have been still long enough for its full image: the
    handler schedules one redraw then.
    """

    def __init__(self, settle_s: float = SETTLE_S, moving_scale: float = MOVING_SCALE) -> None:
        self.settle_s, self.moving_scale = settle_s, moving_scale
        # slot -> [key, time of its last change, last drawn at the moving scale, last drawn while moving]
        self._slots: dict[object, list] = {}

    def scale(self, slot: object, key: bytes, now: float, full_scale: float) -> float:
        st = self._slots.get(slot)
        if st is None:
            self._slots[slot] = [key, -math.inf, False, False]
            return full_scale
        if st[0] != key:
            st[0], st[1] = key, now
        st[3] = now - st[1] < self.settle_s
        st[2] = st[3] and self.moving_scale < full_scale
        return self.moving_scale if st[2] else full_scale

    def moving(self, slot: object) -> bool:
        """Whether the region's last ``scale`` call found its view moving."""
        st = self._slots.get(slot)
        return bool(st is not None and st[3])

    def refine_in(self, now: float) -> float | None:
        """Seconds until the earliest region drawn while moving settles (0 if one already has), None when none is.

        A region counts from its moving draw even at full scale: its splats may have been drawn coarse (a big
        scene's motion copy); where they were not, the refining redraw finds its image unchanged and renders
        nothing."""
        waits = [max(0.0, st[1] + self.settle_s - now) for st in self._slots.values() if st[2] or st[3]]
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
    coarse: bool = False  # drawn from the motion copy (SplatOverlay), not the full scene
    gpu_ms: float = math.nan  # with SplatOverlay.timestamps

    def window_depth(self, pull: float = 0.0) -> np.ndarray:
        return window_depth(self.depth, self.view, pull)


class SplatOverlay:
    """One splat object's GPU renderer (scene uploaded once) and its last image per viewport.

    ``image`` re-renders only when the matrices, the region size, the scale or the detail changed; ``renders``
    counts renders. A renderer passed in stays its owner's (close() leaves it open); one made here is closed with
    the overlay.

    Motion copy. While a moving frame of the full scene cannot keep up (its last full-detail render took longer
    than ``frame_ms``) and the scene has more than ``motion_budget`` splats, moving frames (``image(...,
    moving=True)``) draw a coarse copy of at most that many instead (core/render/coarse.py: the cells of a uniform
    grid merged by moment matching), at MOTION_RESOLUTION of the scale asked for. The copy is built from
    ``motion_scene`` (default ``scene``; the draw handler passes splat_cache's host copy, whose SH is the base colour
    only) on a worker thread started by the first slow render, and uploaded as a second small renderer (with its
    own octree level of detail, drawn at MOTION_LOD_K) by the first frame that draws it. Until then, for scenes
    within the budget and where the full scene fits the frame (a GPU), moving frames are the full scene as before.
    A still frame is always the full scene through ``renderer``: the same image as without a copy, bit for bit.
    """

    def __init__(self, scene: SplatScene | None = None, renderer=None, motion_scene: SplatScene | None = None,
                 motion_budget: int | None = None, frame_ms: float | None = None, background: bool = True) -> None:
        if scene is None and renderer is None:
            raise ValueError("SplatOverlay needs splats: a scene to upload or a renderer holding them")
        self._owns_renderer = renderer is None
        if renderer is None:
            from ...core.render.renderer import SplatRenderer
            renderer = SplatRenderer(scene)
        self.renderer = renderer
        self.renders = 0
        self._last: dict[object, tuple[bytes, OverlayImage]] = {}
        self.motion_budget = MOTION_BUDGET if motion_budget is None else int(motion_budget)
        self.frame_ms = MOTION_FRAME_MS if frame_ms is None else float(frame_ms)
        self.full_ms: float | None = None  # wall time of the last full-detail render
        self.timestamps = False  # benchmarks: GPU time of each render in OverlayImage.gpu_ms
        self.motion_resolution = MOTION_RESOLUTION
        self.motion: MotionCopy | None = None
        self._motion_source = motion_scene if motion_scene is not None else scene
        self._background = background

    def prepare_motion(self) -> None:
        """Start building the motion copy (once) if the scene is over the budget: a thread of its own, seconds of
        numpy (3M splats: ~4 s on this CPU, core/render/coarse.py)."""
        src = self._motion_source
        if self.motion is None and src is not None and src.count > self.motion_budget:
            self.motion = MotionCopy(src, self.motion_budget, self._background)

    def coarse_when_moving(self) -> bool:
        """Whether a moving frame drawn now would be the motion copy."""
        return (self.motion is not None and self.motion.ready() and self.full_ms is not None
                and self.full_ms > self.frame_ms)

    def _key(self, view_matrix, window_matrix, width: int, height: int, scale: float, moving: bool) -> bytes:
        coarse = moving and self.coarse_when_moving()
        return view_key(view_matrix, window_matrix, width, height) + np.float64(scale).tobytes() + bytes([coarse])

    def cached(self, view_matrix, window_matrix, width: int, height: int, scale: float = 1.0,
               slot: object = 0, moving: bool = False) -> OverlayImage | None:
        """The image ``image`` would return without rendering, or None when it would render."""
        last = self._last.get(slot)
        key = self._key(view_matrix, window_matrix, width, height, scale, moving)
        return last[1] if last is not None and last[0] == key else None

    def image(self, view_matrix, window_matrix, width: int, height: int, scale: float = 1.0,
              slot: object = 0, moving: bool = False) -> OverlayImage:
        hit = self.cached(view_matrix, window_matrix, width, height, scale, slot, moving)
        if hit is not None:
            return hit
        coarse = moving and self.coarse_when_moving()
        key = self._key(view_matrix, window_matrix, width, height, scale, moving)
        if coarse:
            scale = max(scale * self.motion_resolution, 1.0 / max(width, height))
        ov = overlay_view(view_matrix, window_matrix, width, height, scale)
        if coarse:
            r = self.motion.renderer(self.renderer)
            res = r.render(ov.batch, depth=True, lod_k=MOTION_LOD_K, timestamps=self.timestamps)
        else:  # the overlay hides splats behind meshes by depth
            res = self.renderer.render(ov.batch, depth=True, timestamps=self.timestamps)
            self.full_ms = res.wall_ms
            if self.full_ms > self.frame_ms:  # too slow to follow the mouse: make the copy, once
                self.prepare_motion()
        self.renders += 1
        img = OverlayImage(res.images[0], ov, res.wall_ms, res.depths[0], scale, coarse,
                           res.timings_ms.get("total", math.nan) if self.timestamps else math.nan)
        self._last[slot] = (key, img)
        return img

    def close(self) -> None:
        self._last.clear()
        if self.motion is not None:
            self.motion.close()
        if self._owns_renderer:
            self.renderer.close()


class MotionCopy:
    """A scene's coarse copy for moving frames (see SplatOverlay): built in numpy (on a daemon thread when
    ``background``), uploaded on first use by the thread that draws, so only that thread touches the GPU."""

    def __init__(self, scene: SplatScene, budget: int, background: bool = True) -> None:
        import threading
        self.budget = budget
        self.coarse = None  # core.render.coarse.CoarseScene, once built
        self.tree = None  # its octree level of detail
        self.build_s = 0.0  # coarse copy and its tree, numpy
        self.error: BaseException | None = None
        self._renderer = None
        self._closed = False
        self._thread = None
        if background:
            self._thread = threading.Thread(target=self._build, args=(scene,), name="gs-ibl motion copy",
                                            daemon=True)
            self._thread.start()
        else:
            self._build(scene)

    def _build(self, scene: SplatScene) -> None:
        import time
        from ...core.render.coarse import coarse_scene
        from ...core.render.lod import build_lod
        try:
            t = time.perf_counter()
            coarse = coarse_scene(scene, self.budget)
            self.tree = build_lod(coarse.scene)
            self.build_s = time.perf_counter() - t
            self.coarse = coarse  # last: ready() reads it without a lock
        except Exception as e:  # noqa: BLE001  a failed copy leaves moving frames at full detail
            self.error = e

    def ready(self) -> bool:
        return self.coarse is not None and not self._closed

    def wait(self, timeout: float | None = None) -> bool:
        """Wait for the build (tests, benchmarks); True once the copy is ready."""
        if self._thread is not None:
            self._thread.join(timeout)
        return self.ready()

    def renderer(self, like):
        """The copy's renderer, made on first use on ``like``'s Vulkan context with its colour rule."""
        if self._renderer is None:
            from ...core.render.renderer import SplatRenderer
            self._renderer = SplatRenderer(self.coarse.scene, like.ctx, near=like.near, lod=self.tree)
        self._renderer.colour_space = like.colour_space  # a push constant: follows the object's setting
        return self._renderer

    def close(self) -> None:
        self._closed = True
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


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


# ---------------------------------------------------------------------------------- compositing into the overlay layer
# Blender draws a 3D View into two layers: the render (the engine's meshes, premultiplied, alpha = coverage, no
# background) and the overlay layer (background, grid, wires, outlines, origins, the 3D cursor: sRGB-encoded 8-bit,
# premultiplied), then shows overlay + (1 - overlay alpha) * render. A POST_VIEW handler draws into the overlay
# layer, with the scene depth bound, after all of Blender's overlays. There the background is stored as
# background * (1 - render coverage) with alpha 0 (Blender's "alpha under" background pass), so a mesh edge pixel
# tells its coverage; lines and dots have alpha > 0 and write depth (wires, the grid at its plane) or not (the
# cursor, origins, outlines).

LINE_CUT = 1.5 / 255.0  # overlay alpha above this: Blender drew lines, dots or text at the pixel
COVERAGE_EPS = 1.0 / 64.0  # a render coverage this close to 0 or 1 counts as none or full
MAX_LAYERS = 4  # splat objects composited per pixel in one pass (more: the plain depth-tested quads)
GRID_TOLERANCE = 1e-2  # a line pixel whose depth is a point of the grid plane within this fraction of its distance
# (Blender writes the grid's depth slightly behind its plane: 1.5-2 cm at 4-7 m, 0.4% of the distance)
EDGE_REACH = 1  # a partly covered pixel without depth takes the nearest depth this many pixels around
LINE_REACH = 2  # a line pixel without depth (an outline) likewise: outlines lie up to two pixels off the mesh


def decode_overlay(overlay8: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """8-bit overlay-layer pixels (sRGB-encoded premultiplied colour, linear alpha) -> (linear rgb, alpha)."""
    o = np.asarray(overlay8, np.float64) / 255.0
    return srgb_to_linear(o[..., :3]), o[..., 3]


def layer_colour(rgba: np.ndarray, exposure: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The renderer's premultiplied linear RGBA -> (premultiplied linear colour with exposure, clipped at the
    coverage, i.e. colour <= 1 before premultiplying; coverage clipped to [0, 1]). What the shader composites: the
    overlay layer is sRGB, the GPU encodes on write."""
    img = np.asarray(rgba, np.float64)
    a = np.clip(img[..., 3], 0.0, 1.0)
    rgb = np.clip(img[..., :3] * 2.0 ** exposure, 0.0, np.maximum(img[..., 3:4], 0.0))
    return rgb, a


def background_coverage(o_rgb: np.ndarray, background) -> np.ndarray:
    """The render's coverage at pixels where the overlay layer holds only the background, o = bg (1 - c), from the
    blue channel (what the draw handler reads back besides alpha; viewport_background says when blue is too dark)."""
    bg = np.broadcast_to(np.asarray(background, np.float64), o_rgb.shape)
    c = np.clip(1.0 - o_rgb[..., 2] / np.maximum(bg[..., 2], 1e-6), 0.0, 1.0)
    c = np.where(c < COVERAGE_EPS, 0.0, np.where(c > 1.0 - COVERAGE_EPS, 1.0, c))
    if np.ptp(bg[..., 2]) == 0.0:  # one colour: its own stored byte is no coverage, however it rounded
        stored = np.round(linear_to_srgb(bg[..., 2]) * 255.0)
        c = np.where(np.round(linear_to_srgb(o_rgb[..., 2]) * 255.0) == stored, 0.0, c)
    return c


def depth_to_world(depth: np.ndarray, view_matrix, window_matrix) -> np.ndarray:
    """Window depths of a region's pixels (rows top first, pixel centres) -> world points: view-space z from the
    projection's depth row (ndc_z = (P22 z + P23) / (P32 z + P33)), x and y from its first two rows, then through the
    inverse view matrix (a rigid transform: no loss of precision near the far plane)."""
    d = np.asarray(depth, np.float64)
    h, w = d.shape
    p = np.asarray(window_matrix, np.float64)
    nx = ((np.arange(w) + 0.5) / w * 2.0 - 1.0)[None, :]
    ny = (1.0 - (np.arange(h) + 0.5) / h * 2.0)[:, None]
    nz = 2.0 * d - 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (p[2, 3] - nz * p[3, 3]) / (nz * p[3, 2] - p[2, 2])
        wc = p[3, 2] * z + p[3, 3]
        x = (nx * wc - p[0, 2] * z - p[0, 3]) / p[0, 0]
        y = (ny * wc - p[1, 2] * z - p[1, 3]) / p[1, 1]
    inv = np.linalg.inv(np.asarray(view_matrix, np.float64))
    pts = np.stack([x, y, z], -1)
    return pts @ inv[:3, :3].T + inv[:3, 3]


def grid_pixels(depth: np.ndarray, line: np.ndarray, view_matrix, window_matrix, normal) -> np.ndarray:
    """Line pixels whose depth is a point of the grid plane (through the origin, ``normal``): the floor grid, which
    writes its depth (rows top first)."""
    pts = depth_to_world(depth, view_matrix, window_matrix)
    eye = np.linalg.inv(np.asarray(view_matrix, np.float64))[:3, 3]
    dist = np.linalg.norm(pts - eye, axis=-1)
    off = np.abs(pts @ np.asarray(normal, np.float64))
    with np.errstate(invalid="ignore"):
        return line & (np.asarray(depth) < 1.0) & (off <= GRID_TOLERANCE * dist + 1e-5)


def disc_mask(width: int, height: int, discs) -> np.ndarray:
    """Pixels (rows top first) whose centre lies within any disc (x, y, r) of region pixel coordinates (x right,
    y up from the bottom edge): where the 3D cursor and object origins are drawn."""
    m = np.zeros((height, width), bool)
    xs = np.arange(width) + 0.5
    ys = height - (np.arange(height) + 0.5)
    for cx, cy, r in discs:
        m |= (xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2 <= r * r
    return m


BACKGROUND_KINDS = {"SINGLE_COLOR": 0, "LINEAR": 1, "RADIAL": 2}


def viewport_background(kind: str, high, low, width: int, height: int) -> np.ndarray:
    """The background Blender's overlay draws in a 3D View region (rows top first, linear): one colour, or its
    theme gradient interpolated in a 1/2.2 power space, bottom (low) to top (high) or centre (high) to corner (low).
    Blender adds a dither of under half an 8-bit step, which is left out."""
    hi, lo = np.asarray(high, np.float64), np.asarray(low, np.float64)
    if kind == "SINGLE_COLOR":
        return np.broadcast_to(hi, (height, width, 3)).copy()
    v = 1.0 - (np.arange(height) + 0.5) / height  # uv.y, 0 at the bottom
    u = (np.arange(width) + 0.5) / width
    ph, pl = np.power(hi, 1 / 2.2), np.power(lo, 1 / 2.2)
    if kind == "LINEAR":
        t = np.broadcast_to(v[:, None], (height, width))[..., None]
        return np.power(pl + (ph - pl) * t, 2.2)
    r = np.hypot(u[None, :] - 0.5, v[:, None] - 0.5)[..., None] * math.sqrt(2.0)
    return np.power(ph + (pl - ph) * r, 2.2)


def _over(layers, order, select):
    """Front-to-back "over" of the selected layers, nearest first: (premultiplied colour, alpha)."""
    h, w = order.shape[1:]
    p = np.zeros((h, w, 3))
    t = np.ones((h, w))
    for i in range(order.shape[0]):
        k = order[i]
        c = np.take_along_axis(layers[0], k[None, ..., None], 0)[0]
        a = np.take_along_axis(layers[1], k[None], 0)[0]
        s = np.take_along_axis(select, k[None], 0)[0]
        p += np.where(s[..., None], t[..., None] * c, 0.0)
        t *= np.where(s, 1.0 - a, 1.0)
    return p, 1.0 - t


def composite(overlay8: np.ndarray, scene_depth: np.ndarray, layers, background, *, use_coverage: bool = True,
              grid=None, discs=(), alpha_cut: float = 1.0 / 255.0) -> tuple[np.ndarray, np.ndarray]:
    """What the overlay layer holds after the splats are drawn into it: numpy reference of the draw shader.

    ``overlay8``: the layer as Blender left it (H, W, 4 uint8, rows top first); ``scene_depth``: the window depth
    there (1: nothing); ``layers``: per splat object (premultiplied linear colour (H, W, 3), coverage (H, W),
    window depth (H, W), 1 where it has none), from layer_colour and window_depth; ``background``: the viewport's
    linear background colour ((3,) or (H, W, 3)), with ``use_coverage`` (Solid and Wireframe shading: the
    background is in the overlay layer, so a pixel's render coverage is known); ``grid``: (view matrix, window
    matrix, plane normal) when the floor grid shows; ``discs``: (x, y, r) where the 3D cursor and origins are drawn.
    Returns (linear premultiplied RGBA to write, written mask: pixels some splats cover at ``alpha_cut``; the others
    keep the layer's bytes).

    Per pixel: the grid's depth does not hide splats (the grid stays under them): Blender writes its plane's depth
    at its lines and where they fade out, so a pixel whose depth is on that plane counts as grid if it has lines or
    no render coverage (a mesh on the floor plane still hides splats). Where the layer holds only the
    background, the render covers c = 1 - o / background of the pixel (blue channel) (a mesh edge: its anti-aliased
    coverage);
    splats nearer than that mesh are drawn over it, and those behind it replace the background in the uncovered
    part, so the mesh edge keeps its anti-aliasing against the splats (out = front + (1 - A_front) (1 - c)
    (behind + (1 - A_behind) background), alpha A_front: the render's c M shows through as before). A partly covered
    pixel whose own depth missed the mesh takes the nearest depth of its 3x3 neighbours (EDGE_REACH). Where Blender
    drew lines (alpha > 0), splats nearer than the lines' depth (or the nearest within LINE_REACH, for lines that
    write none, as outlines; none if a grid pixel is that near: a grid line's faint edge) are drawn over them; inside
    the cursor and origin discs those lines stay on top of the splats instead.
    """
    o8 = np.asarray(overlay8)
    h, w = o8.shape[:2]
    o_rgb, o_a = decode_overlay(o8)
    depth = np.asarray(scene_depth, np.float64)
    line = o_a >= LINE_CUT
    bg = np.broadcast_to(np.asarray(background, np.float64), (h, w, 3))
    cov = background_coverage(o_rgb, bg) if use_coverage else np.ones((h, w))
    if grid is not None:  # the grid writes its plane's depth also where its lines fade out: not under a mesh
        is_grid = grid_pixels(depth, line | (use_coverage & (cov <= 0.0)), *grid)
    else:
        is_grid = np.zeros((h, w), bool)
    d_p = np.where(is_grid, 1.0, depth)

    def nearest(reach):
        pad = np.pad(d_p, reach, mode="edge")
        return np.min([pad[reach + dy:reach + dy + h, reach + dx:reach + dx + w]
                       for dy in range(-reach, reach + 1) for dx in range(-reach, reach + 1)], 0)
    d_edge, d_line_n = nearest(EDGE_REACH), nearest(LINE_REACH)
    pad_g = np.pad(is_grid, LINE_REACH, mode="edge")
    near_grid = np.any([pad_g[LINE_REACH + dy:LINE_REACH + dy + h, LINE_REACH + dx:LINE_REACH + dx + w]
                        for dy in range(-LINE_REACH, LINE_REACH + 1) for dx in range(-LINE_REACH, LINE_REACH + 1)], 0)
    d_line_n = np.where(near_grid, 1.0, d_line_n)  # the faint edge of a grid line, not an outline
    on_top = disc_mask(w, h, discs) & line & ~is_grid

    cols = np.stack([np.asarray(c, np.float64) for c, _a, _d in layers]) if layers else np.zeros((0, h, w, 3))
    alphas = np.stack([np.asarray(a, np.float64) for _c, a, _d in layers]) if layers else np.zeros((0, h, w))
    depths = np.stack([np.asarray(d, np.float64) for _c, _a, d in layers]) if layers else np.zeros((0, h, w))
    present = alphas >= alpha_cut
    order = np.argsort(np.where(present, depths, 2.0), axis=0, kind="stable")

    d_mesh = np.where(cov <= 0.0, 1.0, np.where((d_p < 1.0) | (cov >= 1.0), d_p, d_edge))
    d_line = np.where(on_top, d_p, np.where(d_p < 1.0, d_p, d_line_n))
    split = np.where(line, d_line, d_mesh)
    front = present & (depths < split[None])
    behind = present & ~front
    p_f, a_f = _over((cols, alphas), order, front)
    p_b, a_b = _over((cols, alphas), order, behind)

    out = np.empty((h, w, 4))
    plain = p_f + (1.0 - a_f)[..., None] * (1.0 - cov)[..., None] * (p_b + (1.0 - a_b)[..., None] * bg)
    lines = p_f + (1.0 - a_f)[..., None] * o_rgb
    x_bg = np.where((d_p < 1.0)[..., None], 0.0, bg)
    top = o_rgb + (1.0 - o_a)[..., None] * (p_f - a_f[..., None] * x_bg)
    out[..., :3] = np.where(line[..., None], np.where(on_top[..., None], top, lines), plain)
    out[..., 3] = np.where(line, o_a + (1.0 - o_a) * a_f, a_f)
    return out, present.any(0)


# ------------------------------------------------------------------------------------- what is under the mouse

def mouse_ray(view_matrix, window_matrix, width: int, height: int, x: float, y: float):
    """The world ray (origin, unit direction) of region pixel coordinates (x, y), as Blender's view3d operators
    take event.mval (no half-pixel offset): the eye for a perspective view, the near plane for an orthographic one."""
    v = np.asarray(view_matrix, np.float64)
    p = np.asarray(window_matrix, np.float64)
    inv = np.linalg.inv(p @ v)
    nx, ny = 2.0 * x / width - 1.0, 2.0 * y / height - 1.0
    near = inv @ np.array([nx, ny, -1.0, 1.0])
    far = inv @ np.array([nx, ny, 1.0, 1.0])
    near, far = near[:3] / near[3], far[:3] / far[3]
    d = far - near
    d /= np.linalg.norm(d)
    origin = np.linalg.inv(v)[:3, 3] if abs(p[3, 3]) < 1e-9 else near
    return origin, d


@dataclass(frozen=True)
class SplatHit:
    point: np.ndarray  # world position of the splat surface under the mouse
    distance: float  # along the mouse ray from its origin
    coverage: float  # the image's coverage there


def splat_hit(img: OverlayImage, view_matrix, window_matrix, width: int, height: int, x: float, y: float,
              cut: float = 0.5) -> SplatHit | None:
    """The splat surface under region pixel (x, y) in an overlay image of that view: its depth (distance along the
    render camera's axis) interpolated bilinearly over the neighbouring pixels that hold a splat, None where the
    image's coverage is below ``cut`` (what the overlay counts as opaque)."""
    if img.depth is None:
        return None
    x0, y0, x1, y1 = img.view.ndc_rect
    ih, iw = img.depth.shape
    nx, ny = 2.0 * x / width - 1.0, 2.0 * y / height - 1.0
    u = (nx - x0) / (x1 - x0) * iw - 0.5  # image pixel coordinates of the point, pixel centres at integers
    v = (y1 - ny) / (y1 - y0) * ih - 0.5
    if not (-0.5 <= u <= iw - 0.5 and -0.5 <= v <= ih - 0.5):
        return None
    c0, r0 = int(math.floor(u)), int(math.floor(v))
    fu, fv = u - c0, v - r0
    acc_d = acc_w = acc_a = 0.0
    for dr, dc, wgt in ((0, 0, (1 - fu) * (1 - fv)), (0, 1, fu * (1 - fv)), (1, 0, (1 - fu) * fv), (1, 1, fu * fv)):
        r, c = min(max(r0 + dr, 0), ih - 1), min(max(c0 + dc, 0), iw - 1)
        a = float(img.rgba[r, c, 3])
        acc_a += wgt * a
        d = float(img.depth[r, c])
        if d > 0.0 and a >= cut and wgt > 0.0:
            acc_d += wgt * d
            acc_w += wgt
    if acc_a < cut or acc_w <= 0.0:
        return None
    depth = acc_d / acc_w
    origin, direction = mouse_ray(view_matrix, window_matrix, width, height, x, y)
    view = img.view.batch.views[0]
    along = float(direction @ view.forward)
    if along <= 1e-9:
        return None
    t = (depth - float((origin - img.view.batch.origin) @ view.forward)) / along
    return SplatHit(origin + t * direction, float(t), float(acc_a))


def splats_win(splat_distance: float, mesh_distance: float | None, pull: float = DEPTH_PULL) -> bool:
    """Whether the splats under the mouse are what it points at: no mesh, or a mesh not nearer than the draw lets
    hide them (within DEPTH_PULL of the splat distance the splats win, as drawn)."""
    return mesh_distance is None or mesh_distance >= (1.0 - pull) * splat_distance
