"""Cameras as batches of views sharing one origin: a pinhole camera is one view, a probe cubemap six; several
probes are one batch of six views seen from N origins (``ViewBatch.cubemaps``).

Each view is a rectangle on the plane at distance 1 along ``forward``: pixel (i, j), row 0 at the top, looks along
``forward + s * tan_x * right + t * tan_y * down`` with s, t the pixel centre in (-1, 1). A cubemap face (tan = 1)
is exactly the texel convention of core/cubemap.py, so rendered faces and filters agree by construction.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..cubemap import FACE_BASES
from ..vk.constants import TILE
from .splat_math import PROBE_DILATION_ANGLE


@dataclass(frozen=True)
class View:
    forward: np.ndarray
    right: np.ndarray
    down: np.ndarray
    tan_x: float
    tan_y: float
    width: int
    height: int

    @property
    def tiles(self) -> tuple[int, int]:
        return -(-self.width // TILE), -(-self.height // TILE)

    def pixel_directions(self) -> np.ndarray:
        """(H, W, 3) unnormalised ray directions of the pixel centres."""
        s = ((np.arange(self.width) + 0.5) / self.width * 2 - 1) * self.tan_x
        t = ((np.arange(self.height) + 0.5) / self.height * 2 - 1) * self.tan_y
        tt, ss = np.meshgrid(t, s, indexing="ij")
        return (self.forward[None, None] + ss[..., None] * self.right[None, None]
                + tt[..., None] * self.down[None, None])


@dataclass(frozen=True)
class ViewBatch:
    origin: np.ndarray
    views: tuple[View, ...]
    pixel_angle: float  # radians per pixel at the view centre (the level of detail's unit)
    energy_preserving: bool = False  # probes: dilation keeps each splat's integral (render/splat_math.py)
    # Several probes (ViewBatch.cubemaps): (N, 3) origins, each seeing ``views``; ``origin`` is the first.
    probe_origins: np.ndarray | None = None
    dilation_angle: float | None = None  # the anti-aliasing dilation's pixel angle; None: pixel_angle's

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
        views = tuple(View(FACE_BASES[f, 0], FACE_BASES[f, 1], FACE_BASES[f, 2], 1.0, 1.0, face_size, face_size)
                      for f in range(6))
        return ViewBatch(np.asarray(origin, np.float64).reshape(3), views, 2.0 / face_size, energy_preserving,
                         dilation_angle=PROBE_DILATION_ANGLE if energy_preserving else None)

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
        return ViewBatch(o, (View(f, r, down, tx, ty, int(width), int(height)),), 2.0 * tx / width)
