"""Command line: `python -m gs_ibl_addon COMMAND ...` — render, bake and convert splat scenes without Blender.

File conventions (docs/conventions.md has the details):
  * Splat files: 3DGS PLY (standard or SuperSplat compressed), Niantic SPZ (v2-v4), antimatter15 .splat,
    GaussianSplats3D .ksplat, PlayCanvas SOG (.sog zip or a folder with meta.json), glTF/GLB with
    KHR_gaussian_splatting (docs/formats.md).
  * Bad input (a missing file, an option out of range, an output that cannot be written, a size the machine
    cannot hold) is refused before any work with one line naming the file or option and what to do; exit code 2.
    Outputs appear only complete (written under a temporary name, then moved into place).
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

from .core.settings import (COLOUR_SPACE_CHOICES, COLOUR_SPACE_HELP, DEFAULT_COLOUR_SPACE_CHOICE, DEFAULT_HOLE_FILL,
                            DEFAULT_LOD, DEFAULT_LOD_K, DEFAULT_METHOD, HOLE_FILL_HELP, LOD_HELP, LOD_MODES,
                            DEFAULT_TOLERANCE, METHOD_NAMES, TOLERANCE_HELP)

DESCRIPTION = __doc__
SCENE_HELP = "splat file (.ply, .spz, .splat, .ksplat, .sog, .glb/.gltf) or SOG folder"


def _progress(msg: str, frac: float) -> None:
    print(f"[{100 * frac:3.0f}%] {msg}", file=sys.stderr, flush=True)


def _load(path: str, colour_space: str = "auto"):
    """The scene in ``path``; colour_space other than "auto" overrides what the file declares (--colour-space)."""
    from .core.formats import read_scene
    from .core.formats.colour_space import resolve_colour_space
    t = time.perf_counter()
    scene = read_scene(path)
    scene.colour_space = resolve_colour_space(colour_space, path)
    repairs = ", ".join(f"{k}: {v}" for k, v in scene.repairs.items() if v) or "none"
    print(f"read {path}: {scene.count:,} splats, SH degree {scene.sh_degree}, colour space {scene.colour_space}, "
          f"repairs: {repairs} ({time.perf_counter() - t:.2f} s)", file=sys.stderr)
    return scene


def _vec3(values) -> np.ndarray:
    return np.asarray(values, np.float64)


def finite_float(text: str) -> float:
    """argparse type: an ordinary number (NaN and infinity refused, with a message that says so)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number; give an ordinary number")
    return value


def highlight_gain(text: str) -> float | str:
    """--highlight-gain: 'auto' or a number of at least 1."""
    if text.strip().lower() == "auto":
        return "auto"
    value = finite_float(text)
    if value < 1.0:
        raise argparse.ArgumentTypeError(f"{text!r}: the gain is the highlights' real brightness over 1.0, so 1 "
                                         "(off) or more, or auto")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{value} must be more than 0")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1, with a message that says so."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be 1 or more")
    return value


def tolerance(text: str) -> float:
    """argparse type for --tolerance: a fraction in the range core/tolerance.py validates."""
    from .core.tolerance import check_tolerance
    try:
        return check_tolerance(finite_float(text))
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def size_or_zero(text: str) -> int:
    """argparse type for --face-size and --irradiance-size of bake: 0 (from the tolerance) or a size >= 1."""
    return 0 if text.strip() == "0" else positive_int(text)


def field_of_view(text: str) -> float:
    value = finite_float(text)
    if not 0 < value < 180:
        raise argparse.ArgumentTypeError(f"{value} must lie strictly between 0 and 180 degrees")
    return value


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: the bad argument, what is wrong, where to look (exit code 2)."""

    def error(self, message: str):
        self.exit(2, f"error: {message} (see {self.prog} --help)\n")

    def add_argument(self, *args, **kwargs):
        # Help texts are plain text shared with other front ends ("1%"); argparse %-formats them again at --help.
        if isinstance(kwargs.get("help"), str):
            kwargs["help"] = kwargs["help"].replace("%", "%%")
        return super().add_argument(*args, **kwargs)


OUTPUT_WRITERS = {".ply": ("ply", "write_ply"), ".spz": ("spz", "write_spz"), ".splat": ("splat", "write_splat"),
                  ".sog": ("sog", "write_sog"), ".glb": ("gltf", "write_glb"), ".ksplat": ("ksplat", "write_ksplat")}
# The highest SH degree each writer keeps (docs/formats.md): a converted file says when bands are dropped.
WRITER_SH_DEGREE = {".ply": 3, ".spz": 3, ".splat": 0, ".sog": 0, ".glb": 3, ".ksplat": 2}
# Upper bound of bytes per splat each writer needs (standard PLY with SH degree 3: 62 floats), for the space check.
OUTPUT_BYTES_PER_SPLAT = 62 * 4


def _context():
    """The Vulkan device, made before any file is read: no device means no work, said at once."""
    from .core.vk import get_context
    return get_context()


def cmd_info(a) -> int:
    from .core.formats import check_input
    check_input(a.scene)
    s = _load(a.scene)
    lo, hi = s.bounds()
    from .core.bake import default_probe_position
    print(json.dumps({"file": a.scene, "splats": s.count, "sh_degree": s.sh_degree, "bounds_min": lo.tolist(),
                      "bounds_max": hi.tolist(), "default_probe": default_probe_position(s).tolist(),
                      "repairs": s.repairs}, indent=2))
    return 0


def cmd_render(a) -> int:
    from .core.formats import check_input
    from .core.image_io import write_exr, write_png_preview
    from .core.limits import check_fits, exr_bytes, image_bytes
    from .core.outputs import check_output_file, written_atomically
    from .core.render.renderer import SplatRenderer
    from .core.render.views import ViewBatch
    check_input(a.scene)
    w, h = a.size
    camera, look_at, up = _vec3(a.camera), _vec3(a.look_at), _vec3(a.up)
    if np.linalg.norm(look_at - camera) == 0:
        raise ValueError(f"--look-at {a.look_at}: is the camera position; look at another point")
    if np.linalg.norm(np.cross(look_at - camera, up)) <= 1e-9 * np.linalg.norm(look_at - camera) * max(
            np.linalg.norm(up), 1e-300):
        raise ValueError(f"--up {a.up}: is zero or parallel to the viewing direction; give another up direction")
    ctx = _context()
    check_fits("size", max(w, h), image_bytes(w, h), lambda v: image_bytes(v, v * h // max(w, 1)), ctx,
               f" pixels wide ({w}x{h})")
    check_output_file(a.out, exr_bytes(w, h, 4), "--out", (".exr",))
    if a.depth:
        check_output_file(a.depth, exr_bytes(w, h, 1), "--depth", (".exr",))
    if a.png:
        check_output_file(a.png, 4 * w * h + 4096, "--png", (".png",))
    s = _load(a.scene, a.colour_space)
    batch = ViewBatch.pinhole(camera, look_at, a.fov, w, h, up=up)
    _progress("rendering", 0.3)
    renderer = SplatRenderer(s)
    try:
        res = _advise_on_memory(lambda: renderer.render(batch, timestamps=True, depth=bool(a.depth)),
                                f"rendering {w}x{h} pixels of {s.count:,} splats",
                                "use a smaller --size, or fewer splats")
        image, depth_image = res.images[0], (res.depths[0] if a.depth else None)  # read back before the close
    finally:
        renderer.close()
    with written_atomically(a.out) as out, _maybe(a.depth) as depth, _maybe(a.png) as png:
        write_exr(out, image)
        if depth:
            write_exr(depth, depth_image)
        if png:
            write_png_preview(png, image[..., :3], a.exposure)
    _progress(f"wrote {a.out} ({res.instances:,} splat-tile pairs, GPU {res.timings_ms.get('total', 0):.2f} ms)", 1.0)
    return 0


def _maybe(path: str | None):
    """written_atomically(path), or a context giving None when the output was not asked for."""
    import contextlib

    from .core.outputs import written_atomically
    return written_atomically(path) if path else contextlib.nullcontext(None)


def _advise_on_memory(work, what: str, advice: str):
    """Run ``work()``; an out-of-memory error (numpy's or the GPU's) becomes one MemoryError with advice."""
    from .core.limits import out_of_memory_advice
    try:
        return work()
    except Exception as e:
        better = out_of_memory_advice(e, what, advice)
        if better is None:
            raise
        raise better from None


def cmd_cubemap(a) -> int:
    from .core.bake import check_probe_position
    from .core.cubemap import FACE_NAMES
    from .core.formats import check_input
    from .core.image_io import write_exr
    from .core.limits import check_fits, cube_bytes, exr_bytes
    from .core.outputs import check_output_dir, staged_folder
    from .core.probe import cube_to_latlong
    from .core.render.renderer import render_cubemap
    check_input(a.scene)
    probe = check_probe_position(a.probe)
    n = a.face_size
    ctx = _context()
    check_fits("face_size", n, cube_bytes(n, 1), lambda v: cube_bytes(v, 1), ctx, "^2 faces")
    check_output_dir(a.out, 6 * exr_bytes(n, n, 4) + exr_bytes(4 * n, 2 * n, 4), "--out")
    s = _load(a.scene, a.colour_space)
    _progress(f"rendering six {n}x{n} faces", 0.3)
    cube, res = _advise_on_memory(lambda: render_cubemap(s, probe, n, timestamps=True),
                                  f"rendering six {n}^2 faces of {s.count:,} splats",
                                  "use a smaller --face-size, or fewer splats")
    with staged_folder(a.out) as stage:
        for f, name in enumerate(FACE_NAMES):
            write_exr(os.path.join(stage, f"face_{'pos' if name[0] == '+' else 'neg'}{name[1].lower()}.exr"), cube[f])
        write_exr(os.path.join(stage, "radiance.exr"), cube_to_latlong(cube, 4 * n))
    holes = float(1 - cube[..., 3].mean())
    _progress(f"wrote {a.out}: 6 faces + radiance.exr; GPU {res.timings_ms.get('total', 0):.2f} ms; "
              f"mean uncovered {100 * holes:.2f}%", 1.0)
    return 0


def cmd_bake(a) -> int:
    from .core.bake import (ProbeSettings, bake_probe, check_fits_device, check_probe_position, check_settings,
                            default_probe_position, estimate_output_bytes)
    from .core.formats import check_input
    from .core.outputs import check_output_dir, check_output_file
    from .core.preview import write_preview
    from .core.probe import write_probe
    from .core.probe.result import check_probe_folder
    # Everything that can be known wrong is refused here, before the file is read or anything rendered.
    fill = a.hole_fill or ("constant" if a.hole_colour else DEFAULT_HOLE_FILL)
    if fill == "constant" and not a.hole_colour:
        raise ValueError("--hole-fill constant: give the colour with --hole-colour R G B (linear radiance)")
    if a.hole_colour and fill != "constant":
        raise ValueError(f"--hole-colour: only used with --hole-fill constant, not {fill}")
    check_input(a.scene)
    settings = ProbeSettings(method=a.method, face_size=a.face_size, irradiance_size=a.irradiance_size,
                             tolerance=a.tolerance, glossy=a.glossy, lod=a.lod, lod_k=a.lod_k, hole_fill=fill,
                             hole_colour=tuple(a.hole_colour or (0.0, 0.0, 0.0)), highlight_gain=a.highlight_gain,
                             lights=a.lights)
    check_settings(settings)
    probe = None if a.probe is None else check_probe_position(a.probe)
    ctx = _context()
    check_fits_device(settings, ctx)
    check_output_dir(a.out, estimate_output_bytes(settings, a.half, a.faces), "--out")
    check_probe_folder(a.out, "--out")
    if a.preview:
        check_output_file(a.preview, 4 << 20, "--preview", (".png",))
    s = _load(a.scene, a.colour_space)
    check_fits_device(settings, ctx, s.count, s.sh.shape[1])
    if probe is None:
        probe = default_probe_position(s)
        print(f"no --probe given: using the splats' opacity-weighted centre of mass {np.round(probe, 4).tolist()}",
              file=sys.stderr)
    result = bake_probe(s, probe, settings, progress=_progress)
    title = os.path.basename(a.scene)

    def preview(path: str) -> None:
        write_preview(result, path, title=title)

    from .core.stage_times import StageTimes, stage_text
    with StageTimes(None, result.timings_ms).stage("files"), _maybe(a.preview) as outside:
        if outside:
            preview(outside)
        written = write_probe(result, a.out, half=a.half, cube_faces=a.faces,
                              extra=None if a.preview else {"preview.png": preview})
    from .core.probe.holes import hole_fill_text, hole_warning
    t = result.timings_ms
    print(f"method {result.settings['method']} (asked: {a.method}), faces {result.settings['face_size']}^2, "
          f"irradiance {result.settings['irradiance_size']}^2, cubemap GPU {t.get('render_total', 0):.2f} ms, "
          f"filter {t.get('irradiance', 0):.2f} ms, device {result.device}")
    print(stage_text(t))
    from .core.tolerance import plan_text
    line = plan_text(result.settings)
    if line:
        print(line)
    from .core.probe.highlights import highlight_text
    from .core.probe.lights import lights_text
    from .core.probe.near import near_warning
    print(hole_fill_text(result.hole_fill))
    for line in (highlight_text(result.highlights), lights_text(result.lights)):
        if line:
            print(line)
    for warning in (hole_warning(result.hole_fill), near_warning(result.near_splats)):
        if warning:
            print(f"warning: {warning}", file=sys.stderr)
    print("wrote " + ", ".join(sorted(written)) + (f" and {a.preview}" if a.preview else "") + f" in {a.out}")
    return 0


def cmd_convert(a) -> int:
    import importlib

    from .core.formats import check_input
    from .core.outputs import check_output_file, written_atomically
    ext = os.path.splitext(a.output)[1].lower()
    if ext not in OUTPUT_WRITERS:
        raise ValueError(f"output {a.output}: cannot write '{ext}' files (give a name ending in "
                         f"{', '.join(OUTPUT_WRITERS)})")
    check_input(a.input, "input")
    check_output_file(a.output, 0, "output")  # before reading a large input for nothing
    s = _load(a.input)
    check_output_file(a.output, s.count * OUTPUT_BYTES_PER_SPLAT, "output")
    module, name = OUTPUT_WRITERS[ext]
    writer = getattr(importlib.import_module(f".core.formats.{module}", __package__), name)
    with written_atomically(a.output) as tmp:
        writer(tmp, s)
    print(f"wrote {a.output}: {s.count:,} splats")
    keeps = WRITER_SH_DEGREE[ext]
    if s.sh_degree > keeps:
        bands = f"band {keeps + 1}" if s.sh_degree == keeps + 1 else f"bands {keeps + 1}-{s.sh_degree}"
        better = ", ".join(e for e, d in WRITER_SH_DEGREE.items() if d >= s.sh_degree)
        print(f"note: {ext} keeps SH degree {keeps}: the input's SH {bands} (view-dependent colour) were dropped; "
              f"{better} keep them", file=sys.stderr)
    return 0


def cmd_sample(a) -> int:
    from .core.formats.axes import BLENDER_AXES, axes_comment
    from .core.formats.ply import write_ply
    from .core.outputs import check_output_file, written_atomically
    from .core.synthetic import sample_environment
    check_output_file(a.out, 64 << 20, "out", (".ply",))
    s = sample_environment().with_sh_degree(0)
    with written_atomically(a.out) as tmp:
        write_ply(tmp, s, comments=(axes_comment(*BLENDER_AXES),))  # made Z up: imports upright; declares linear
    print(f"wrote {a.out}: {s.count:,} splats (the generated sample environment)")
    return 0


def _colour_space_option(q: argparse.ArgumentParser) -> None:
    q.add_argument("--colour-space", default=DEFAULT_COLOUR_SPACE_CHOICE, choices=COLOUR_SPACE_CHOICES,
                   help=COLOUR_SPACE_HELP)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m gs_ibl_addon", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", help="Vulkan device: an index, part of its name, 'gpu' or 'cpu' (lavapipe); "
                                    "default: a discrete GPU, else any (also GS_IBL_DEVICE)")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    q = sub.add_parser("info", help="what a splat file holds (count, SH degree, bounds, repairs made on reading)")
    q.add_argument("scene", help=SCENE_HELP)
    q.set_defaults(fn=cmd_info)

    q = sub.add_parser("render", help="render one pinhole view of the splats to an EXR (RGBA, alpha = coverage)")
    q.add_argument("scene", help=SCENE_HELP)
    q.add_argument("--camera", nargs=3, type=finite_float, required=True, metavar=("X", "Y", "Z"),
                   help="camera position")
    q.add_argument("--look-at", nargs=3, type=finite_float, required=True, metavar=("X", "Y", "Z"),
                   help="point looked at")
    q.add_argument("--up", nargs=3, type=finite_float, default=(0.0, 0.0, 1.0), metavar=("X", "Y", "Z"),
                   help="up direction (default +Z, Blender's; most 3DGS captures are -Y up: use 0 -1 0)")
    q.add_argument("--fov", type=field_of_view, default=60.0, help="horizontal field of view in degrees (default 60)")
    q.add_argument("--size", nargs=2, type=positive_int, default=(640, 480), metavar=("W", "H"),
                   help="image size in pixels")
    q.add_argument("--out", required=True, help="output EXR path")
    q.add_argument("--png", help="also write an 8-bit sRGB preview PNG here")
    q.add_argument("--depth", help="also write a one-channel EXR of depth here: distance along the view axis of what "
                                   "each pixel shows (coverage-weighted), 0 where it shows nothing")
    q.add_argument("--exposure", type=finite_float, default=0.0, help="exposure (stops) of the PNG preview")
    _colour_space_option(q)
    q.set_defaults(fn=cmd_render)

    q = sub.add_parser("cubemap", help="render the six cube faces seen from a probe point to EXRs, plus a lat-long")
    q.add_argument("scene", help=SCENE_HELP)
    q.add_argument("--probe", nargs=3, type=finite_float, required=True, metavar=("X", "Y", "Z"), help="probe position")
    q.add_argument("--face-size", type=positive_int, default=256, help="pixels per face side (default 256)")
    q.add_argument("--out", required=True, help="output folder (face_posx.exr ... face_negz.exr, radiance.exr)")
    _colour_space_option(q)
    q.set_defaults(fn=cmd_cubemap)

    q = sub.add_parser("bake", help="bake a light probe: radiance, irradiance (E/pi), SH, probe.json, preview.png")
    q.add_argument("scene", help=SCENE_HELP)
    q.add_argument("--probe", nargs=3, type=finite_float, metavar=("X", "Y", "Z"),
                   help="probe position (default: the splats' opacity-weighted centre of mass)")
    q.add_argument("--method", default=DEFAULT_METHOD, choices=METHOD_NAMES,
                   help="irradiance filter: auto (= exact, the most accurate at the same cost), exact (every "
                        "texel integrated with its exact solid angle), sh (9 SH coefficients: rings near small "
                        "bright sources), conv (cosine convolution, the thesis's method), box (box-filtered "
                        "mips, fast and rough); docs/accuracy.md compares them")
    q.add_argument("--face-size", type=size_or_zero, default=0,
                   help="radiance face size (default 0: the smallest estimated to meet --tolerance)")
    q.add_argument("--irradiance-size", type=size_or_zero, default=0,
                   help="irradiance cube face size (default 0: 8, 16 or 32, the smallest whose reads between texels "
                        "meet --tolerance)")
    q.add_argument("--tolerance", type=tolerance, default=DEFAULT_TOLERANCE, help=TOLERANCE_HELP)
    q.add_argument("--glossy", action="store_true", help="also write GGX prefiltered radiance (ggx_*.exr)")
    q.add_argument("--lod", default=DEFAULT_LOD, choices=LOD_MODES, help=LOD_HELP)
    q.add_argument("--lod-k", type=positive_float, default=DEFAULT_LOD_K,
                   help=f"with --lod auto: merged splats are drawn once their cell spans at most this many pixels "
                        f"(default {DEFAULT_LOD_K:g}; smaller is more accurate and slower)")
    q.add_argument("--hole-fill", choices=("mean", "constant", "black"), help=HOLE_FILL_HELP)
    q.add_argument("--hole-colour", nargs=3, type=finite_float, metavar=("R", "G", "B"),
                   help="linear radiance of the holes (implies --hole-fill constant)")
    q.add_argument("--highlight-gain", type=highlight_gain, default=1.0, metavar="GAIN",
                   help="clipped highlights (colours at the top of the range, as 8-bit photos leave windows and "
                        "lamps) times GAIN, the light's real brightness over 1.0 (2^stops); auto: estimated from the "
                        "brightest unclipped directions (a guess, often low); default 1 (off)")
    q.add_argument("--lights", type=int, default=0, choices=range(0, 9), metavar="N",
                   help="split up to N (0-8) bright compact regions (sun, lamp, window) off the probe as lights, "
                        "listed in probe.json for Blender sun lights with shadows; default 0")
    q.add_argument("--faces", action="store_true", help="also write every cube face as its own EXR")
    q.add_argument("--half", action="store_true", help="write half-float EXRs (smaller; max 65504)")
    q.add_argument("--out", required=True, help="output folder")
    q.add_argument("--preview", help="preview PNG path (default OUT/preview.png)")
    _colour_space_option(q)
    q.set_defaults(fn=cmd_bake)

    q = sub.add_parser("convert",
                       help="convert between splat formats (writes .ply, .spz, .splat, .sog, .glb or .ksplat)")
    q.add_argument("input", help=SCENE_HELP)
    q.add_argument("output", help="output file; the format follows its extension")
    q.set_defaults(fn=cmd_convert)

    q = sub.add_parser("sample", help="write the generated sample environment (a lit room) as a 3DGS PLY")
    q.add_argument("out", help="output .ply path")
    q.set_defaults(fn=cmd_sample)
    return p


def _one_line(e: BaseException) -> str:
    """The message of a refused input as one line; settings errors name their command-line option."""
    from .core.bake import BadSetting
    from .core.limits import TooBig
    text = " ".join(str(e).split())
    if isinstance(e, (BadSetting, TooBig)):
        return f"--{e.option.replace('_', '-')}: {text}"
    return text


def _terminate_as_interrupt() -> None:
    """SIGTERM (a job killed, a timeout) unwinds like Ctrl-C, so temporary outputs are removed on the way out."""
    import signal
    import threading

    def interrupt(_sig, _frame):
        raise KeyboardInterrupt

    if threading.current_thread() is threading.main_thread() and hasattr(signal, "SIGTERM"):
        signal.signal(signal.SIGTERM, interrupt)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.device:
        os.environ["GS_IBL_DEVICE"] = args.device
    from .core.formats import SplatFormatError
    from .core.vk import VulkanUnavailable
    _terminate_as_interrupt()
    try:
        return args.fn(args)
    except (SplatFormatError, VulkanUnavailable, OSError, ValueError, MemoryError) as e:
        print(f"error: {_one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted; nothing partial was left in place", file=sys.stderr)
        return 130
