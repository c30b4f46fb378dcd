"""Command line: `python -m gs_ibl_addon COMMAND ...` — render, bake and convert splat scenes without Blender.

File conventions (docs/conventions.md has the details):
  * Splat files: 3DGS PLY (standard or SuperSplat compressed), Niantic SPZ (v2-v4), antimatter15 .splat.
  * Coordinates are the file's own; Blender's Z-up world is assumed for lat-long images (+Z at the top row).
  * Images are scene-linear float EXR (OpenImageIO). Cube faces are +X, -X, +Y, -Y, +Z, -Z with the OpenGL
    orientation; lat-long images use Blender's equirectangular mapping (centre column = +X, u = 0.25 = +Y).
  * Alpha in rendered images is coverage: directions with alpha < 1 see through the splats (holes).
  * irradiance.exr holds E/pi: a white diffuse surface with that normal shows exactly that value.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

DESCRIPTION = __doc__


def _progress(msg: str, frac: float) -> None:
    print(f"[{100 * frac:3.0f}%] {msg}", file=sys.stderr, flush=True)


def _load(path: str):
    from .core.formats import read_scene
    t = time.perf_counter()
    scene = read_scene(path)
    repairs = ", ".join(f"{k}: {v}" for k, v in scene.repairs.items() if v) or "none"
    print(f"read {path}: {scene.count:,} splats, SH degree {scene.sh_degree}, repairs: {repairs} "
          f"({time.perf_counter() - t:.2f} s)", file=sys.stderr)
    return scene


def _vec3(values) -> np.ndarray:
    return np.asarray(values, np.float64)


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1, with a message that says so."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be 1 or more")
    return value


def face_size(text: str) -> int:
    """argparse type for --face-size of bake: 0 (search) or a size >= 1."""
    return 0 if text.strip() == "0" else positive_int(text)


OUTPUT_WRITERS = {".ply": ("ply", "write_ply"), ".spz": ("spz", "write_spz"), ".splat": ("splat", "write_splat")}


def cmd_info(a) -> int:
    s = _load(a.scene)
    lo, hi = s.bounds()
    from .core.bake import default_probe_position
    print(json.dumps({"file": a.scene, "splats": s.count, "sh_degree": s.sh_degree, "bounds_min": lo.tolist(),
                      "bounds_max": hi.tolist(), "default_probe": default_probe_position(s).tolist(),
                      "repairs": s.repairs}, indent=2))
    return 0


def cmd_render(a) -> int:
    from .core.image_io import write_exr, write_png_preview
    from .core.render.renderer import SplatRenderer
    from .core.render.views import ViewBatch
    s = _load(a.scene)
    batch = ViewBatch.pinhole(_vec3(a.camera), _vec3(a.look_at), a.fov, a.size[0], a.size[1], up=_vec3(a.up))
    _progress("rendering", 0.3)
    res = SplatRenderer(s).render(batch, timestamps=True)
    write_exr(a.out, res.images[0])
    if a.depth:
        write_exr(a.depth, res.depths[0])
    if a.png:
        write_png_preview(a.png, res.images[0][..., :3], a.exposure)
    _progress(f"wrote {a.out} ({res.instances:,} splat-tile pairs, GPU {res.timings_ms.get('total', 0):.2f} ms)", 1.0)
    return 0


def cmd_cubemap(a) -> int:
    from .core.cubemap import FACE_NAMES
    from .core.image_io import write_exr
    from .core.probe import cube_to_latlong
    from .core.render.renderer import render_cubemap
    s = _load(a.scene)
    os.makedirs(a.out, exist_ok=True)
    _progress(f"rendering six {a.face_size}x{a.face_size} faces", 0.3)
    cube, res = render_cubemap(s, _vec3(a.probe), a.face_size, timestamps=True)
    for f, name in enumerate(FACE_NAMES):
        write_exr(os.path.join(a.out, f"face_{'pos' if name[0] == '+' else 'neg'}{name[1].lower()}.exr"), cube[f])
    write_exr(os.path.join(a.out, "radiance.exr"), cube_to_latlong(cube, 4 * a.face_size))
    holes = float(1 - cube[..., 3].mean())
    _progress(f"wrote {a.out}: 6 faces + radiance.exr; GPU {res.timings_ms.get('total', 0):.2f} ms; "
              f"mean uncovered {100 * holes:.2f}%", 1.0)
    return 0


def cmd_bake(a) -> int:
    from .core.bake import ProbeSettings, bake_probe, default_probe_position
    from .core.preview import write_preview
    from .core.probe import write_probe
    s = _load(a.scene)
    if a.probe is None:
        probe = default_probe_position(s)
        print(f"no --probe given: using the splats' opacity-weighted centre of mass {np.round(probe, 4).tolist()}",
              file=sys.stderr)
    else:
        probe = _vec3(a.probe)
    settings = ProbeSettings(method=a.method, face_size=a.face_size, irradiance_size=a.irradiance_size,
                             tolerance=a.tolerance, glossy=a.glossy)
    result = bake_probe(s, probe, settings, progress=_progress)
    written = write_probe(result, a.out, half=a.half, cube_faces=a.faces)
    preview = a.preview or os.path.join(a.out, "preview.png")
    write_preview(result, preview, title=os.path.basename(a.scene))
    t = result.timings_ms
    print(f"method {result.settings['method']} (asked: {a.method}), faces {result.settings['face_size']}^2, "
          f"cubemap GPU {t.get('render_total', 0):.2f} ms, filter {t.get('irradiance', 0):.2f} ms, "
          f"holes {100 * result.hole_fraction:.2f}%, device {result.device}")
    if result.hole_fraction > 0.01:
        print(f"warning: {100 * result.hole_fraction:.1f}% of directions from the probe see no splat (holes); "
              "they add no light", file=sys.stderr)
    print("wrote " + ", ".join(sorted(written)) + f", {os.path.basename(preview)} in {a.out}")
    return 0


def cmd_convert(a) -> int:
    import importlib

    from .core.formats import SplatFormatError
    ext = os.path.splitext(a.output)[1].lower()
    if ext not in OUTPUT_WRITERS:  # before reading a large input for nothing
        raise SplatFormatError(f"{a.output}: cannot write '{ext}' files (use {', '.join(OUTPUT_WRITERS)})")
    s = _load(a.input)
    module, name = OUTPUT_WRITERS[ext]
    getattr(importlib.import_module(f".core.formats.{module}", __package__), name)(a.output, s)
    print(f"wrote {a.output}: {s.count:,} splats")
    return 0


def cmd_sample(a) -> int:
    from .core.formats.axes import BLENDER_AXES, axes_comment
    from .core.formats.ply import write_ply
    from .core.synthetic import sample_environment
    s = sample_environment().with_sh_degree(0)
    write_ply(a.out, s, comments=(axes_comment(*BLENDER_AXES),))  # made Z up: imports upright
    print(f"wrote {a.out}: {s.count:,} splats (the generated sample environment)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m gs_ibl_addon", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", help="Vulkan device: an index, part of its name, 'gpu' or 'cpu' (lavapipe); "
                                    "default: a discrete GPU, else any (also GS_IBL_DEVICE)")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    q = sub.add_parser("info", help="what a splat file holds (count, SH degree, bounds, repairs made on reading)")
    q.add_argument("scene", help="splat file (.ply, .spz, .splat)")
    q.set_defaults(fn=cmd_info)

    q = sub.add_parser("render", help="render one pinhole view of the splats to an EXR (RGBA, alpha = coverage)")
    q.add_argument("scene", help="splat file (.ply, .spz, .splat)")
    q.add_argument("--camera", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"), help="camera position")
    q.add_argument("--look-at", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"), help="point looked at")
    q.add_argument("--up", nargs=3, type=float, default=(0.0, 0.0, 1.0), metavar=("X", "Y", "Z"),
                   help="up direction (default +Z, Blender's; most 3DGS captures are -Y up: use 0 -1 0)")
    q.add_argument("--fov", type=float, default=60.0, help="horizontal field of view in degrees (default 60)")
    q.add_argument("--size", nargs=2, type=positive_int, default=(640, 480), metavar=("W", "H"),
                   help="image size in pixels")
    q.add_argument("--out", required=True, help="output EXR path")
    q.add_argument("--png", help="also write an 8-bit sRGB preview PNG here")
    q.add_argument("--depth", help="also write a one-channel EXR of depth here: distance along the view axis of what "
                                   "each pixel shows (coverage-weighted), 0 where it shows nothing")
    q.add_argument("--exposure", type=float, default=0.0, help="exposure (stops) of the PNG preview")
    q.set_defaults(fn=cmd_render)

    q = sub.add_parser("cubemap", help="render the six cube faces seen from a probe point to EXRs, plus a lat-long")
    q.add_argument("scene", help="splat file (.ply, .spz, .splat)")
    q.add_argument("--probe", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"), help="probe position")
    q.add_argument("--face-size", type=positive_int, default=256, help="pixels per face side (default 256)")
    q.add_argument("--out", required=True, help="output folder (face_posx.exr ... face_negz.exr, radiance.exr)")
    q.set_defaults(fn=cmd_cubemap)

    q = sub.add_parser("bake", help="bake a light probe: radiance, irradiance (E/pi), SH, probe.json, preview.png")
    q.add_argument("scene", help="splat file (.ply, .spz, .splat)")
    q.add_argument("--probe", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="probe position (default: the splats' opacity-weighted centre of mass)")
    q.add_argument("--method", default="auto", choices=["auto", "sh", "conv", "box", "exact"],
                   help="irradiance filter: auto (= exact, the most accurate at the same cost), exact (every "
                        "texel integrated with its exact solid angle), sh (9 SH coefficients: rings near small "
                        "bright sources), conv (cosine convolution, the thesis's method), box (box-filtered "
                        "mips, fast and rough); docs/accuracy.md compares them")
    q.add_argument("--face-size", type=face_size, default=0,
                   help="radiance face size (default 0: start at 32 and double until the irradiance changes by "
                        "less than --tolerance)")
    q.add_argument("--irradiance-size", type=positive_int, default=16, help="irradiance cube face size (default 16)")
    q.add_argument("--tolerance", type=float, default=0.01, help="relative RMS irradiance change that ends the face-size search (default 0.01)")
    q.add_argument("--glossy", action="store_true", help="also write GGX prefiltered radiance (ggx_*.exr)")
    q.add_argument("--faces", action="store_true", help="also write every cube face as its own EXR")
    q.add_argument("--half", action="store_true", help="write half-float EXRs (smaller; max 65504)")
    q.add_argument("--out", required=True, help="output folder")
    q.add_argument("--preview", help="preview PNG path (default OUT/preview.png)")
    q.set_defaults(fn=cmd_bake)

    q = sub.add_parser("convert", help="convert between splat formats (writes .ply, .spz or .splat)")
    q.add_argument("input", help="splat file (.ply, .spz, .splat)")
    q.add_argument("output", help="output file; the format follows its extension")
    q.set_defaults(fn=cmd_convert)

    q = sub.add_parser("sample", help="write the generated sample environment (a lit room) as a 3DGS PLY")
    q.add_argument("out", help="output .ply path")
    q.set_defaults(fn=cmd_sample)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.device:
        os.environ["GS_IBL_DEVICE"] = args.device
    from .core.formats import SplatFormatError
    from .core.vk import VulkanUnavailable
    try:
        return args.fn(args)
    except (SplatFormatError, VulkanUnavailable, OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
