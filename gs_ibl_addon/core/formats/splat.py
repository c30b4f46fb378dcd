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
from functools import partial

import numpy as np

from ..scene import SplatScene, rgb_to_sh_dc, sh_dc_to_rgb
from .checks import check_input, fail
from .repair import clamp_scales, new_counts, normalise_quaternions, reported

RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])
assert RECORD.itemsize == 32
_ALPHA_EPS = 0.25 / 255.0  # a quarter step: inside the byte's rounding interval, so it re-encodes to the same byte
_REEXPORT = "re-export the .splat, or export a 3DGS PLY instead"
_DAMAGED = "the file is damaged or not a .splat file"

_fail = partial(fail, todo=_REEXPORT)  # this format's usual advice; a call passes todo= for other advice


def read_splat(path: str | os.PathLike) -> SplatScene:
    """Decode a .splat file into an activated SplatScene (SH degree 0)."""
    path = check_input(path)
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
                          ".splat stores exp(log scale), which is never negative", todo=_DAMAGED)
    # The repairs read_ply makes: splats with non-finite values are dropped (only positions and scales are floats
    # here), too-small scales clamped (exp() of a very negative log scale underflows), zero quaternions replaced by
    # the identity, each counted under the same repair name.
    counts = new_counts()
    finite = np.isfinite(rec["position"]).all(1) & np.isfinite(rec["scale"]).all(1)
    if not finite.any():
        raise _fail(path, f"all {n} splats have non-finite positions or scales", todo=_DAMAGED)
    if not finite.all():
        counts["dropped_nonfinite"] = int(n - finite.sum())
        rec = rec[finite]
    positions = np.ascontiguousarray(rec["position"])
    scales = np.ascontiguousarray(rec["scale"])  # a copy (the field is strided), clamped in place below
    clamp_scales(scales, counts)
    rotations = normalise_quaternions(rec["rotation"].astype(np.float32) - 128.0, counts)

    rgba = rec["rgba"].astype(np.float32) / 255.0
    sh = rgb_to_sh_dc(rgba[:, :3])[:, None, :]
    opacities = np.clip(rgba[:, 3], _ALPHA_EPS, 1 - _ALPHA_EPS)
    return SplatScene(positions, scales, rotations, opacities, sh, source=path, repairs=reported(counts))


def write_splat(path: str | os.PathLike, scene: SplatScene) -> None:
    """Write ``scene`` as .splat in its own order (the DC colour is clamped to [0, 1]; SH rest is dropped)."""
    path = os.fspath(path)
    rec = np.empty(scene.count, RECORD)
    rec["position"] = scene.positions
    rec["scale"] = scene.scales
    rgb = np.clip(sh_dc_to_rgb(scene.sh[:, 0]), 0.0, 1.0)
    alpha = np.clip(np.asarray(scene.opacities, np.float64), 0.0, 1.0)
    rec["rgba"] = np.round(np.concatenate([rgb, alpha[:, None]], 1) * 255.0).astype(np.uint8)
    q = np.asarray(scene.rotations, np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    rec["rotation"] = np.clip(np.round(q * 128.0 + 128.0), 0, 255).astype(np.uint8)
    rec.tofile(path)
