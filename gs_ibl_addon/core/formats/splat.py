"""antimatter15 ``.splat``: no header, 32 bytes per splat, little-endian.

float32 position (3), float32 scale (3, linear: exp of the PLY value), uint8 RGBA (RGB = the DC colour
0.5 + SH_C0 * f_dc clamped to [0, 1] times 255; A = sigmoid(opacity) * 255), uint8 quaternion (w, x, y, z), each
stored as q * 128 + 128 clamped to [0, 255]. Degree 0 only: view-dependent colour is not stored.
Positions are in the 3DGS PLY frame (RDF), like SplatScene.

With no magic number, a wrong file is recognised by its size (a multiple of 32) and by what it decodes to
(no negative scales, some finite splats). Repairs follow read_ply: ``dropped_nonfinite``, ``clamped_scales``,
``identity_rotations``.
"""
from __future__ import annotations

import os

import numpy as np

from ..scene import SH_C0, SplatScene
from . import SplatFormatError
from .ply import MIN_SCALE

RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])
assert RECORD.itemsize == 32
_ALPHA_EPS = 0.25 / 255.0  # a quarter step: inside the byte's rounding interval, so it re-encodes to the same byte
_REEXPORT = "re-export the .splat, or export a 3DGS PLY instead"
_DAMAGED = "the file is damaged or not a .splat file"


def _fail(path: str, what: str, todo: str = _REEXPORT) -> SplatFormatError:
    return SplatFormatError(f"{path}: {what} ({todo})")


def read_splat(path: str | os.PathLike) -> SplatScene:
    """Decode a .splat file into an activated SplatScene (SH degree 0)."""
    path = os.fspath(path)
    size = os.path.getsize(path)
    if size == 0:
        raise _fail(path, "the file is empty")
    if size % RECORD.itemsize:
        raise _fail(path, f"{size} bytes is not a whole number of 32-byte splats ({size % 32} bytes left over): "
                          "truncated, or not a .splat file")
    rec = np.fromfile(path, RECORD)
    n = len(rec)
    if (rec["scale"] < 0).any():
        bad = (rec["scale"] < 0).any(1)
        raise _fail(path, f"{int(bad.sum())} of {n} splats have negative scales (first: splat {int(np.argmax(bad))}); "
                          ".splat stores exp(log scale), which is never negative", _DAMAGED)
    repairs = {}
    # As read_ply does: splats with non-finite values are dropped, too-small scales clamped, zero quaternions
    # replaced by the identity, each counted under the same repair name.
    finite = np.isfinite(rec["position"]).all(1) & np.isfinite(rec["scale"]).all(1)
    if not finite.any():
        raise _fail(path, f"all {n} splats have non-finite positions or scales", _DAMAGED)
    if not finite.all():
        repairs["dropped_nonfinite"] = int(n - finite.sum())
        rec = rec[finite]
    positions = np.ascontiguousarray(rec["position"])
    scales = np.ascontiguousarray(rec["scale"])
    small = scales < MIN_SCALE  # exp() of a very negative log scale underflows; such a splat is invisible anyway
    if small.any():
        repairs["clamped_scales"] = int(small.any(1).sum())
        scales = np.maximum(scales, MIN_SCALE)

    q = rec["rotation"].astype(np.float32) - 128.0
    norm = np.linalg.norm(q, axis=1)
    degenerate = norm == 0
    if degenerate.any():
        repairs["identity_rotations"] = int(degenerate.sum())
        q[degenerate] = (1.0, 0.0, 0.0, 0.0)
        norm[degenerate] = 1.0
    rotations = q / norm[:, None]

    rgba = rec["rgba"].astype(np.float32) / 255.0
    sh = ((rgba[:, :3] - 0.5) / np.float32(SH_C0))[:, None, :]
    opacities = np.clip(rgba[:, 3], _ALPHA_EPS, 1 - _ALPHA_EPS)
    return SplatScene(positions, scales, rotations.astype(np.float32), opacities, sh.astype(np.float32),
                      source=path, repairs=repairs)


def write_splat(path: str | os.PathLike, scene: SplatScene) -> None:
    """Write ``scene`` as .splat in its own order (the DC colour is clamped to [0, 1]; SH rest is dropped)."""
    path = os.fspath(path)
    rec = np.empty(scene.count, RECORD)
    rec["position"] = scene.positions
    rec["scale"] = scene.scales
    rgb = np.clip(0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64), 0.0, 1.0)
    alpha = np.clip(np.asarray(scene.opacities, np.float64), 0.0, 1.0)
    rec["rgba"] = np.round(np.concatenate([rgb, alpha[:, None]], 1) * 255.0).astype(np.uint8)
    q = np.asarray(scene.rotations, np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    rec["rotation"] = np.clip(np.round(q * 128.0 + 128.0), 0, 255).astype(np.uint8)
    rec.tofile(path)
