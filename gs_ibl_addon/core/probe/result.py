"""ProbeResult (everything a baked probe produced) and write_probe (EXR + JSON files in one folder).

Files written by ``write_probe``:
  radiance.exr        lat-long radiance (Blender equirectangular mapping), RGB, scene-linear
  irradiance.exr      lat-long irradiance, value = E(n)/pi (a white Lambertian surface's outgoing radiance)
  ggx_<k>.exr         lat-long GGX-prefiltered radiance per roughness level (when present)
  faces/<map>_<face>.exr  the cube faces themselves, when cube_faces=True (+X, -X, +Y, -Y, +Z, -Z)
  probe.json          SH coefficients, settings, splat count, timings, device, hole fraction, conventions
"""
from __future__ import annotations

import dataclasses
import json
import os
from typing import Any

import numpy as np

from .. import cubemap
from ..image_io import write_exr
from ..sh import degree_of
from .latlong import cube_to_latlong

CONVENTIONS = {
    "colour": "scene-linear Rec.709 RGB, float",
    "irradiance": "value = E(n)/pi: a white Lambertian surface under it has outgoing radiance = value; "
                  "a uniform environment of radiance L gives L",
    "latlong": "Blender equirectangular (Environment Texture): centre column +X, u=0.25 +Y, top row +Z; "
               "u = 0.5 - atan2(y, x)/(2 pi), v_top = acos(z)/pi; world space, Z up",
    "cube_faces": "order +X,-X,+Y,-Y,+Z,-Z; OpenGL/Vulkan orientation; texel (i, j) of N: "
                  "dir = forward + s*right + t*down, s = 2(i+0.5)/N-1, t = 2(j+0.5)/N-1 (core/cubemap.py)",
    "sh": "real orthonormal SH with Condon-Shortley phase (= 3DGS basis for l<=3), order l=0.., m=-l..l; "
          "coefficients are of the radiance; irradiance E/pi = sum_l (A_l/pi) w_l sum_m L_lm Y_lm(n), "
          "A_0=pi, A_1=2pi/3, A_2=pi/4",
    "holes": "directions without splats are black (premultiplied alpha); hole_fraction = share of the sphere",
}


@dataclasses.dataclass
class ProbeResult:
    radiance: np.ndarray  # (6, N, N, 3 or 4) radiance cube
    irradiance: np.ndarray  # (6, M, M, 3) E/pi
    sh_coefficients: np.ndarray | None = None  # (K, 3) radiance SH
    prefiltered: list[np.ndarray] = dataclasses.field(default_factory=list)  # GGX cubes, one per roughness
    roughness: list[float] = dataclasses.field(default_factory=list)
    settings: dict[str, Any] = dataclasses.field(default_factory=dict)
    timings_ms: dict[str, float] = dataclasses.field(default_factory=dict)
    splat_count: int = 0
    device: str = ""
    hole_fraction: float = 0.0


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


def write_probe(result: ProbeResult, out_dir: str | os.PathLike, half: bool = False, cube_faces: bool = False,
                latlong_width: int | None = None) -> dict[str, str]:
    """Write a probe's files into out_dir (created if missing); returns {name: path} of what was written.

    latlong_width defaults to 4 x the radiance face size (enough to keep the cube's detail).
    """
    out_dir = os.fspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    rad = np.asarray(result.radiance)[..., :3]
    width = latlong_width or 4 * rad.shape[1]
    irr_width = latlong_width or max(64, 4 * result.irradiance.shape[1])
    written: dict[str, str] = {}

    def put(name: str, image: np.ndarray) -> None:
        path = os.path.join(out_dir, name)
        write_exr(path, image, half=half)
        written[name] = path

    put("radiance.exr", cube_to_latlong(rad, width))
    put("irradiance.exr", cube_to_latlong(result.irradiance[..., :3], irr_width))
    for k, cube in enumerate(result.prefiltered):
        put(f"ggx_{k}.exr", cube_to_latlong(cube[..., :3], latlong_width or max(64, 4 * cube.shape[1])))
    if cube_faces:
        os.makedirs(os.path.join(out_dir, "faces"), exist_ok=True)
        maps = [("radiance", np.asarray(result.radiance)), ("irradiance", result.irradiance)]
        maps += [(f"ggx_{k}", c) for k, c in enumerate(result.prefiltered)]
        for label, cube in maps:
            for f, fname in enumerate(cubemap.FACE_NAMES):
                sign = "pos" if fname[0] == "+" else "neg"
                put(os.path.join("faces", f"{label}_{sign}{fname[1].lower()}.exr"), cube[f])
    meta = {
        "conventions": CONVENTIONS,
        "sh_coefficients": None if result.sh_coefficients is None else result.sh_coefficients,
        "sh_order": None if result.sh_coefficients is None else degree_of(len(result.sh_coefficients)),
        "roughness": list(result.roughness),
        "radiance_face_size": int(rad.shape[1]),
        "irradiance_face_size": int(result.irradiance.shape[1]),
        "settings": result.settings,
        "timings_ms": result.timings_ms,
        "splat_count": int(result.splat_count),
        "device": result.device,
        "hole_fraction": float(result.hole_fraction),
        "files": sorted(written),
    }
    path = os.path.join(out_dir, "probe.json")
    with open(path, "w", encoding="utf-8") as f:
        json.dump(_jsonable(meta), f, indent=2)
    written["probe.json"] = path
    return written
