"""ProbeResult (everything a baked probe produced) and write_probe (EXR + JSON files in one folder).

Files written by ``write_probe``:
  radiance.exr        lat-long radiance (Blender equirectangular mapping), RGB, scene-linear
  irradiance.exr      lat-long irradiance, value = E(n)/pi (a white Lambertian surface's outgoing radiance)
  ggx_<k>.exr         lat-long GGX-prefiltered radiance per roughness level (when present)
  faces/<map>_<face>.exr  the cube faces themselves, when cube_faces=True (+X, -X, +Y, -Y, +Z, -Z)
  probe.json          SH coefficients, settings, splat count, timings, device, hole fraction, conventions, and
                      "files": what this bake wrote (how the next bake into the folder knows what it may remove)
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
from typing import Any, Callable

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
    "holes": "directions without splats: alpha < 1 in the radiance cube; hole_fraction = share of the sphere; "
             "hole_fill = how their light was filled before filtering (method mean|constant|environment|black, "
             "value = the fill's mean RGB over the holes, fraction = hole_fraction)",
    "lights": "bright compact regions split off the radiance (their light is not in the EXRs): direction (unit, "
              "toward the light), solid_angle (sr), angle (deg, disc diameter), irradiance (RGB, at normal "
              "incidence = a Blender sun's Strength x Color), share (of the probe's power)",
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
    hole_fill: dict[str, Any] | None = None  # {"method", "value", "fraction"} (probe.holes.fill_holes); None: unfilled
    highlights: dict[str, Any] | None = None  # clipped highlights' gain (probe.highlights); None: none applied
    lights: list[dict[str, Any]] = dataclasses.field(default_factory=list)  # split off (probe.lights)
    near_splats: dict[str, Any] | None = None  # the probe's distance from splats in sigmas (probe.near)


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


PROBE_JSON = "probe.json"
# Names write_probe (and the command line's default preview) can write; an earlier bake's are known by probe.json.
_OURS = re.compile(r"^(radiance|irradiance|ggx_\d+)\.exr$|^preview\.png$|^probe\.json$"
                   r"|^faces/(radiance|irradiance|ggx_\d+)_(pos|neg)[xyz]\.exr$")


def _looks_ours(out_dir: str) -> list[str]:
    found = []
    for folder in (out_dir, os.path.join(out_dir, "faces")):
        if os.path.isdir(folder):
            rel = os.path.relpath(folder, out_dir)
            for name in os.listdir(folder):
                name = name if rel == "." else f"{rel}/{name}"
                if _OURS.match(name) and os.path.isfile(os.path.join(out_dir, name)):
                    found.append(name)
    return sorted(found)


def earlier_bake_files(out_dir: str | os.PathLike) -> list[str] | None:
    """The files an earlier bake wrote in out_dir, from its probe.json (None: no readable probe.json)."""
    path = os.path.join(os.fspath(out_dir), PROBE_JSON)
    try:
        with open(path, encoding="utf-8") as f:
            files = json.load(f).get("files")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(files, list):
        return None
    # Only plain names under out_dir that we could have written: a hand-edited list never deletes anything else.
    listed = {str(n).replace(os.sep, "/") for n in files}
    return sorted(n for n in listed | {PROBE_JSON, "preview.png"} if _OURS.match(n))


def check_probe_folder(out_dir: str | os.PathLike, option: str | None = None) -> None:
    """Refuse an output folder holding probe files that no probe.json says gs-ibl wrote: they would sit, stale,
    beside the new bake, and we do not delete what we cannot prove is ours."""
    out_dir = os.fspath(out_dir)
    if not os.path.isdir(out_dir):
        return
    found = _looks_ours(out_dir)
    known = earlier_bake_files(out_dir)
    strangers = [n for n in found if known is None or n not in known]
    if strangers:
        from ..outputs import OutputError
        who = f"{option} {out_dir}" if option else out_dir
        shown = ", ".join(strangers[:4]) + (f" and {len(strangers) - 4} more" if len(strangers) > 4 else "")
        raise OutputError(f"{who}: holds {shown}, which no probe.json there lists as written by gs-ibl, so a new "
                          "bake would leave them beside its own files; choose a new or empty folder, or delete them")


def write_probe(result: ProbeResult, out_dir: str | os.PathLike, half: bool = False, cube_faces: bool = False,
                latlong_width: int | None = None,
                extra: dict[str, Callable[[str], None]] | None = None) -> dict[str, str]:
    """Write a probe's files into out_dir (created if missing); returns {name: path} of what was written.

    latlong_width defaults to 4 x the radiance face size (enough to keep the cube's detail). ``extra`` maps more
    file names to functions writing them (given the path), e.g. a preview; they are listed in probe.json too.
    Everything is written into a temporary folder inside out_dir first and moved into place only when all of it
    is complete; then the files an earlier bake listed in its probe.json that this one did not write are removed,
    so the folder never mixes two bakes (``check_probe_folder`` refuses folders whose files we cannot vouch for).
    """
    from ..outputs import remove_quietly, staged_folder
    out_dir = os.fspath(out_dir)
    names: list[str] = []

    def clear_earlier(new: list[str]) -> None:
        for name in earlier_bake_files(out_dir) or []:
            if name not in new:
                remove_quietly(os.path.join(out_dir, name))
        faces = os.path.join(out_dir, "faces")
        if os.path.isdir(faces) and not os.listdir(faces) and not any(n.startswith("faces/") for n in new):
            os.rmdir(faces)

    with staged_folder(out_dir, last=PROBE_JSON, before_move=clear_earlier) as stage:
        names = _write_all(result, stage, half, cube_faces, latlong_width, extra or {})
    return {name: os.path.join(out_dir, name) for name in names}


def _write_all(result: ProbeResult, out_dir: str, half: bool, cube_faces: bool, latlong_width: int | None,
               extra: dict[str, Callable[[str], None]]) -> list[str]:
    rad = np.asarray(result.radiance)[..., :3]
    width = latlong_width or 4 * rad.shape[1]
    irr_width = latlong_width or max(64, 4 * result.irradiance.shape[1])
    written: list[str] = []

    def put(name: str, image: np.ndarray) -> None:
        write_exr(os.path.join(out_dir, name), image, half=half)
        written.append(name)

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
                put(f"faces/{label}_{sign}{fname[1].lower()}.exr", cube[f])
    for name, write in extra.items():
        write(os.path.join(out_dir, name))
        written.append(name)
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
        "hole_fill": result.hole_fill or {"method": "black", "value": [0.0, 0.0, 0.0],
                                          "fraction": float(result.hole_fraction)},
        "highlights": result.highlights,
        "lights": list(result.lights),
        "near_splats": result.near_splats,
        "files": sorted(written),
    }
    with open(os.path.join(out_dir, PROBE_JSON), "w", encoding="utf-8") as f:
        json.dump(_jsonable(meta), f, indent=2)
    written.append(PROBE_JSON)
    return written
