"""Holes: directions from the probe that meet no splat (alpha < 1 in the rendered cube), given light by a stated rule.

A hole has no data: left black it says "no light comes from there", which is the one answer sure to be wrong (an
open window, a probe outside the capture). So the bake fills the uncovered share of each texel, (1 - alpha) times
a fill radiance, before filtering, and records what it did (ProbeResult.hole_fill, probe.json "hole_fill"):

  mean         the solid-angle mean of the covered radiance (the default: the light the probe does see, spread
               into what it does not; neutral for a small gap, a guess for a large one)
  constant     a colour the user gives (``hole_colour``)
  environment  a radiance per direction supplied by the caller (bake_probe's ``hole_radiance``; meant for
               Blender's previous World, which the extension does not pass yet)
  black        nothing (the renderer's raw output)
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .. import cubemap
from ..settings import HOLE_FILLS
# A probe seeing more than this share of holes is mostly lit by its fill, not by the splats: say so loudly.
MOSTLY_HOLES = 0.5


def covered_mean(cube: np.ndarray) -> np.ndarray:
    """(3,) solid-angle mean radiance of the covered directions of a premultiplied RGBA cube (zeros when none)."""
    w = cubemap.texel_solid_angles(cube.shape[1])[None, ..., None]
    covered = float(np.sum(np.clip(cube[..., 3:4], 0.0, 1.0) * w))
    if covered <= 0.0:
        return np.zeros(3)
    return np.sum(cube[..., :3].astype(np.float64) * w, axis=(0, 1, 2)) / covered


def fill_holes(cube: np.ndarray, method: str, colour=(0.0, 0.0, 0.0),
               radiance: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[np.ndarray, dict]:
    """(the RGBA cube with (1 - alpha) x fill added to its RGB (alpha kept: it still shows coverage), a record
    {"method", "value": the fill's mean RGB over the holes, "fraction": hole share of the sphere})."""
    if method not in HOLE_FILLS:
        raise ValueError(f"hole fill {method!r}: use one of {', '.join(HOLE_FILLS)}")
    cube = np.asarray(cube, np.float32)
    n = cube.shape[1]
    w = cubemap.texel_solid_angles(n)[None, ..., None]
    missing = 1.0 - np.clip(cube[..., 3:4], 0.0, 1.0) if cube.shape[-1] == 4 else np.zeros(cube.shape[:3] + (1,))
    fraction = float(np.sum(missing * w) / (4.0 * np.pi))
    if method == "environment":
        if radiance is None:
            raise ValueError("hole fill 'environment' needs the environment's radiance (bake_probe hole_radiance)")
        fill = np.asarray(radiance(cubemap.face_directions(n).reshape(-1, 3)), np.float64).reshape(6, n, n, 3)
    elif method == "mean":
        fill = covered_mean(cube)
    elif method == "constant":
        fill = np.asarray(colour, np.float64).reshape(3)
    else:
        fill = np.zeros(3)
    fill = np.broadcast_to(fill, cube.shape[:3] + (3,))
    weight = float(np.sum(missing * w))
    value = np.sum(fill * missing * w, axis=(0, 1, 2)) / weight if weight > 0 else fill.reshape(-1, 3).mean(0)
    out = cube.copy()
    if method != "black" and fraction > 0.0:
        out[..., :3] += (missing * fill).astype(np.float32)
    return out, {"method": method, "value": [float(v) for v in value], "fraction": fraction}


def hole_fill_text(record: dict | None) -> str:
    """One line for summaries: 'hole fill: mean of the covered directions (0.41, 0.38, 0.3) over 2.1% of the
    sphere'."""
    if not record or record.get("fraction", 0.0) == 0.0:
        return "hole fill: none needed (every direction meets splats)"
    pct = 100 * record["fraction"]
    if record.get("method") == "black":
        return f"hole fill: black (no light) over {pct:.1f}% of the sphere"
    rgb = ", ".join(f"{v:.3g}" for v in record.get("value", ()))
    how = {"mean": "mean of the covered directions", "constant": "constant",
           "environment": "environment"}.get(record["method"], record["method"])
    return f"hole fill: {how} ({rgb}) over {pct:.1f}% of the sphere"


def hole_warning(record: dict | None) -> str | None:
    """A warning when holes matter (over 1% of the sphere), louder when they are most of it; None otherwise."""
    if not record or record.get("fraction", 0.0) <= 0.01:
        return None
    head = f"the probe sees holes: {100 * record['fraction']:.1f}% of directions have no splat"
    light = "no light (black)" if record.get("method") == "black" else f"the {record['method']} fill's light"
    if record["fraction"] > MOSTLY_HOLES:
        return (f"{head}: THE PROBE IS PROBABLY OUTSIDE THE SPLATS, so its light is mostly {light}, not the "
                "capture's; move the probe inside the splats")
    return f"{head}; they carry {light}"
