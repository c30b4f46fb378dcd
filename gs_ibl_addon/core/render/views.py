"""Cameras as batches of views sharing one origin: a pinhole camera is one view, a probe cubemap six; several
probes are one batch of six views seen from N origins (``ViewBatch.cubemaps``).

Each view is a rectangle on the plane at distance 1 along ``forward``: pixel (i, j), row 0 at the top, looks along
``forward + (s * tan_x + cx) * right + (t * tan_y + cy) * down`` with s, t the pixel centre in (-1, 1) of the
frame's pixel grid. A cubemap face (tan = 1, no offset) is exactly the texel convention of core/cubemap.py, so
rendered faces and filters agree by construction.

Cameras may be off centre (a lens shift: cx, cy) and may render only a window of their frame (a render border or
crop: the view's ``width`` x ``height`` pixels start at pixel (x0, y0) of a ``frame_width`` x ``frame_height``
grid). The GPU computes a pixel's (s, t) from its frame pixel, in the frame's own arithmetic, so a window's pixels
are the full frame's pixels bit for bit (ViewBatch.camera).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..cubemap import FACE_BASES
from ..vk.constants import SORT_RADIAL, SORT_VIEW_DEPTH, TILE
from .splat_math import PROBE_DILATION_ANGLE


@dataclass(frozen=True)
class View:
    forward: np.ndarray
    right: np.ndarray
    down: np.ndarray
    tan_x: float
    tan_y: float
    width: int  # the pixels this view renders
    height: int
    cx: float = 0.0  # the frame's centre in the image plane at distance 1, along right and down (a lens shift)
    cy: float = 0.0
    x0: int = 0  # the view's first column and row in the frame's pixel grid (a render border / crop)
    y0: int = 0
    frame_width: int = 0  # the frame's pixel grid; 0: the view's own width / height (the whole frame)
    frame_height: int = 0

    @property
    def grid(self) -> tuple[int, int]:
        """The frame's pixel grid (width, height) the view's pixels are taken from."""
        return self.frame_width or self.width, self.frame_height or self.height

    @property
    def tiles(self) -> tuple[int, int]:
        return -(-self.width // TILE), -(-self.height // TILE)

    def image_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """(s, t) image-plane coordinates (distance 1; tan units plus the centre offset) of the view's pixel
        columns (W,) and rows (H,), float64."""
        fw, fh = self.grid
        s = ((np.arange(self.width) + self.x0 + 0.5) / fw * 2 - 1) * self.tan_x + self.cx
        t = ((np.arange(self.height) + self.y0 + 0.5) / fh * 2 - 1) * self.tan_y + self.cy
        return s, t

    def pixel_directions(self) -> np.ndarray:
        """(H, W, 3) unnormalised ray directions of the pixel centres (forward part 1)."""
        s, t = self.image_coords()
        tt, ss = np.meshgrid(t, s, indexing="ij")
        return (self.forward[None, None] + ss[..., None] * self.right[None, None]
                + tt[..., None] * self.down[None, None])


@lru_cache(maxsize=16)
def _cube_views(face_size: int) -> tuple[View, ...]:
    """The six faces' views at one size: one tuple per size, so a renderer packs it once (renderer.py
    _views_buffer_data); its arrays are FACE_BASES' rows, read-only."""
    return tuple(View(FACE_BASES[f, 0], FACE_BASES[f, 1], FACE_BASES[f, 2], 1.0, 1.0, face_size, face_size)
                 for f in range(6))


@dataclass(frozen=True)
class ViewBatch:
    origin: np.ndarray
    views: tuple[View, ...]
    pixel_angle: float  # radians per pixel at the view centre (the level of detail's unit)
    energy_preserving: bool = False  # probes: dilation keeps each splat's integral (render/splat_math.py)
    # Several probes (ViewBatch.cubemaps): (N, 3) origins, each seeing ``views``; ``origin`` is the first.
    probe_origins: np.ndarray | None = None
    dilation_angle: float | None = None  # the anti-aliasing dilation's pixel angle; None: pixel_angle's
    # The order splats composite in (vk/constants.py): SORT_RADIAL (probes: cubemap, cubemaps; a face taken out of
    # a cube keeps it) or SORT_VIEW_DEPTH (camera views: camera, pinhole). None: view depth for a batch of one view
    # that is not energy-preserving, radial otherwise (a batch built field by field, as the viewport's).
    sort: int | None = None

    def __post_init__(self) -> None:
        if self.sort is None:
            camera = len(self.views) == 1 and not self.energy_preserving
            object.__setattr__(self, "sort", SORT_VIEW_DEPTH if camera else SORT_RADIAL)
        if self.sort not in (SORT_RADIAL, SORT_VIEW_DEPTH):
            raise ValueError(f"sort {self.sort!r} must be SORT_RADIAL ({SORT_RADIAL}) or SORT_VIEW_DEPTH "
                             f"({SORT_VIEW_DEPTH})")
        if self.sort == SORT_VIEW_DEPTH and len(self.views) != 1:
            raise ValueError(f"a batch of {len(self.views)} views sorts by distance (SORT_RADIAL): depth along a "
                             "view's axis orders one view")

    @property
    def dilation(self) -> float:
        """The angle the anti-aliasing dilation is sized by (render/splat_math.py)."""
        return self.pixel_angle if self.dilation_angle is None else float(self.dilation_angle)

    @property
    def origins(self) -> np.ndarray:
        """(N, 3) float64: the origin of every probe of the batch (one row for a plain batch)."""
        return self.origin[None] if self.probe_origins is None else self.probe_origins

    @property
    def n_probes(self) -> int:
        return 1 if self.probe_origins is None else len(self.probe_origins)

    @staticmethod
    def cubemap(origin, face_size: int, energy_preserving: bool = True) -> "ViewBatch":
        """The six faces of a probe. Their images are light to integrate: the dilation preserves energy and has one
        size whatever the face (PROBE_DILATION_ANGLE), so every face size samples the same radiance and a coarse
        face is that radiance read at its texel centres. ``energy_preserving=False``: 3DGS's look instead, dilated
        by this face's pixel."""
        if int(face_size) < 1:
            raise ValueError(f"cube face size {face_size} must be 1 or more")
        views = _cube_views(int(face_size))
        return ViewBatch(np.asarray(origin, np.float64).reshape(3), views, 2.0 / face_size, energy_preserving,
                         dilation_angle=PROBE_DILATION_ANGLE if energy_preserving else None, sort=SORT_RADIAL)

    @staticmethod
    def cubemaps(origins, face_size: int) -> "ViewBatch":
        """The six faces of each of N probes (``origins`` (N, 3)), rendered in one submission
        (SplatRenderer.render_probes): faces +X, -X, +Y, -Y, +Z, -Z of probe 0, then of probe 1, ..."""
        try:
            o = np.asarray(origins, np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"probe positions must be an (N, 3) array of numbers, got {origins!r:.80}") from None
        if o.ndim == 1 and o.shape == (3,):
            o = o[None]
        if o.ndim != 2 or o.shape[1] != 3 or len(o) == 0:
            raise ValueError(f"probe positions must be an (N, 3) array with N >= 1, got shape {o.shape}")
        bad = np.flatnonzero(~np.all(np.isfinite(o), 1))
        if len(bad):
            raise ValueError(f"probe position {int(bad[0])} {o[bad[0]].tolist()} is not finite (NaN or infinity); "
                             f"{len(bad)} of {len(o)} are: give ordinary numbers")
        one = ViewBatch.cubemap(o[0], face_size)
        return replace(one, probe_origins=o.copy()) if len(o) > 1 else one

    @staticmethod
    def pinhole(position, look_at, fov_deg: float, width: int, height: int, up=(0.0, 0.0, 1.0)) -> "ViewBatch":
        """A perspective camera; ``fov_deg`` is the horizontal field of view; ``up`` defaults to Blender's +Z."""
        if int(width) < 1 or int(height) < 1:
            raise ValueError(f"image size {width}x{height} must be at least 1x1")
        o = np.asarray(position, np.float64).reshape(3)
        f = np.asarray(look_at, np.float64).reshape(3) - o
        if not np.linalg.norm(f) > 0:
            raise ValueError("camera position and look-at point coincide")
        f /= np.linalg.norm(f)
        r = np.cross(f, np.asarray(up, np.float64))
        if np.linalg.norm(r) < 1e-6:  # looking straight along up: pick any perpendicular
            r = np.cross(f, [1.0, 0.0, 0.0] if abs(f[0]) < 0.9 else [0.0, 1.0, 0.0])
        r /= np.linalg.norm(r)
        down = np.cross(f, r)
        if not 0 < fov_deg < 179:
            raise ValueError(f"field of view {fov_deg} degrees is outside (0, 179)")
        tx = float(np.tan(np.radians(fov_deg) / 2))
        ty = tx * height / width
        return ViewBatch(o, (View(f, r, down, tx, ty, int(width), int(height)),), 2.0 * tx / width,
                         sort=SORT_VIEW_DEPTH)

    @staticmethod
    def camera(cam_to_world, tan_x: float, tan_y: float, width: int, height: int, shift=(0.0, 0.0),
               window=None) -> "ViewBatch":
        """A perspective camera as Blender describes one, for its final renders.

        ``cam_to_world``: the camera's 4x4 world matrix (Blender's convention: it looks down its local -Z, +Y up, +X
        right; scale and shear are taken out). ``tan_x``, ``tan_y``: tangents of the half angles the frame spans
        (with Blender's sensor fit and pixel aspect already applied). ``width`` x ``height``: the frame's pixels
        (resolution times its percentage). ``shift``: (cx, cy), where the frame's centre lies in the image plane at
        distance 1, along the camera's +X (right) and +Y (up): Blender's lens shift times the sensor-fit size,
        cx = shift_x * 2 * tan(half the fitted angle). ``window``: (x0, y0, x1, y1) renders only columns x0..x1-1
        and rows y0..y1-1 of the frame, rows counted from the top (a render border or crop; Blender counts its
        border from the bottom): the image is (y1 - y0) x (x1 - x0), each pixel exactly the full frame's.
        The anti-aliasing dilation is sized by the frame's pixel (2 tan_x / width)."""
        try:
            m = np.asarray(cam_to_world, np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"camera matrix must be a 4x4 array of numbers, got {cam_to_world!r:.80}") from None
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError(f"camera matrix must be a finite 4x4 array, got shape {m.shape}")
        width, height = int(width), int(height)
        if width < 1 or height < 1:
            raise ValueError(f"image size {width}x{height} must be at least 1x1")
        tx, ty = float(tan_x), float(tan_y)
        if not (0 < tx < 1e6 and 0 < ty < 1e6):
            raise ValueError(f"tan_x {tan_x!r} and tan_y {tan_y!r} must be positive and finite (a perspective camera)")
        cx, cy = (float(v) for v in shift)
        if not (np.isfinite(cx) and np.isfinite(cy)):
            raise ValueError(f"lens shift {shift!r} must be finite")
        x0, y0, x1, y1 = (0, 0, width, height) if window is None else (int(v) for v in window)
        if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
            raise ValueError(f"window {window!r} must be (x0, y0, x1, y1) with 0 <= x0 < x1 <= {width} and "
                             f"0 <= y0 < y1 <= {height} (pixels of the {width}x{height} frame, rows from the top)")
        f = -m[:3, 2]
        if not np.linalg.norm(f) > 0:
            raise ValueError("camera matrix has no view direction (its Z column is zero)")
        f = f / np.linalg.norm(f)
        r = m[:3, 0] - (m[:3, 0] @ f) * f  # Gram-Schmidt: the matrix's X made orthogonal to the view direction
        if not np.linalg.norm(r) > 1e-9:
            raise ValueError("camera matrix has no right direction (its X column is zero or along Z)")
        r = r / np.linalg.norm(r)
        down = np.cross(f, r)  # -Y: Blender's camera is right-handed (X right, Y up, looking down -Z)
        view = View(f, r, down, tx, ty, x1 - x0, y1 - y0, cx, -cy, x0, y0, width, height)
        return ViewBatch(m[:3, 3].copy(), (view,), 2.0 * tx / width, sort=SORT_VIEW_DEPTH)
