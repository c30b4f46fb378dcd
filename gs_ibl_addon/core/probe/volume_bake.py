"""The light volume's bake: every probe of a grid rendered (radiance and depth) in batched submissions, then turned
into its two octahedral maps (volume.py's layout) by fixed linear maps of the cube's texels.

- Render: SplatRenderer.render(ViewBatch.cubemaps(probes, face), depth=True), as many probes a submission as one
  group of the device holds (the renderer writes depth for one group at a time); the renderer holds the whole scene
  (every splat object that lights it, merged by the caller: core takes arrays), so every object lights and shadows
  every probe.
- Irradiance: E/pi at each texel is linear in the cube's radiance. The texels are fitted by least squares so that
  the *bilinear lookup* (volume.bilinear_map) reproduces the cosine-lobe irradiance over FIT_DIRECTIONS directions
  ((B^T B)^-1 B^T C, B the bilinear weights at those directions, C their cosine lobes over the cube's texels):
  bilinear lookups of point-sampled texels err twice as much at the map's folds (volume.py). The radiance is
  box-averaged to IRR_FACE^2 first; one (IRR^2, 6 IRR_FACE^2) matrix, built once a session; a chunk is one matmul.
- Visibility: each texel's radial distance r = z sqrt(1 + s^2 + t^2) (the renderer's depth is the coverage-weighted
  z along the face's axis), the far distance where coverage < COVERED, filtered into (mean r, mean r^2) by DDGI's
  lobe max(0, d.w)^VIS_SHARPNESS (normalised per texel): another fixed matrix.
- A probe inside something (splats all round it within half a spacing: the inside of an object) gets moments
  (0, 0): every point is then behind its first surface and the lookup drops it (the Chebyshev test gives 0).
- Holes (directions with no splat) are black unless ``hole_colour`` gives their radiance; probes with more than
  HOLE_REPORT of their sphere open are reported.
"""
from __future__ import annotations

import functools
import time
from typing import Callable

import numpy as np

from ..cubemap import face_directions, face_st, texel_solid_angles
from ..synthetic import fibonacci_sphere
from .grid import GridSpec
from .volume import (COVERED, FAR_FACTOR, IRR, VIS, VIS_SHARPNESS, LightVolume, bilinear_taps, grid_maps,
                     probe_positions, spec_spacing, texel_directions)

# The cube face each probe renders. 16^2 faces alias small bright splats (a window, a lamp): each probe's light is off
# by a few percent its own way, which reads per point, not in a camera half's mean, and its cells' centre errors
# ask for bricks the light does not need. A sphere at the sample room's centre (256 points against per-point 32^2
# probes, 2026-12-05, lavapipe): 16^2 faces rms 3.0% per point with 316 probes (20 bricks), 32^2 faces 0.98% with
# 91 (no brick), 10.4 against 8.3 s. Over the five places (volume_bench.py --faces 16,32): 512 probes per-point
# mean 2.5% / 2.6%, 1,024 probes 2.4% / 1.5%; the bake 1.2-1.3x as long at equal probes.
DEFAULT_FACE = 32
# Faces above these are box-averaged to them before the maps: irradiance needs no finer texels (analytic cubes' fitted
# maps read 0.22% rms at 16^2 and at 32^2, tests/test_volume_bake.py), visibility's lobe of ~10 degrees a little finer.
IRR_FACE, VIS_FACE = 16, 32
FIT_DIRECTIONS = 4000  # the least-squares fit's directions (~14 a texel of a 17^2 map)
INSIDE_FRACTION = 0.8  # a probe seeing splats within half a spacing over this share of its sphere is inside one
HOLE_REPORT = 0.05
# bake_probes' maps: True on the GPU (gpu_volume_maps: reads back the maps, not the cubes and depths) for faces up
# to VIS_FACE, False on the host (the cubes read back into maps_from_cubes), None: on the GPU unless the device is a
# CPU. On lavapipe the host's BLAS wins: 300 probes of the sample room at 16^2 took 2.1 s of GPU maps against 49 ms
# of numpy (the readback is a memcpy there), 2026-12-05, load ~4.6. On an H100 (gpu_run.sh volume, 2026-12-05:
# tests/test_gpu_volume_maps.py passed on the device) the sample room's 511-probe volume over three meshes took
# 111-114 ms with GPU maps against 180-200 ms with the cubes read back into numpy.
GPU_MAPS: bool | None = None


@functools.lru_cache(maxsize=8)
def irradiance_matrix(face: int, n: int = IRR) -> np.ndarray:
    """(n^2, 6 face^2) float32: cube radiance (texels in FACE order, row-major) -> the octahedral E/pi texels fitted
    to the bilinear lookup: (B^T B)^-1 B^T C, B the bilinear weights at the fit directions (four a row: summed by
    texel without the dense B), C the cosine lobes of the fit directions over the cube's texels."""
    fit = fibonacci_sphere(FIT_DIRECTIONS)
    dirs = face_directions(face).reshape(-1, 3)
    sa = np.broadcast_to(texel_solid_angles(face), (6, face, face)).reshape(-1)
    idx, w = bilinear_taps(n, fit)
    gram = np.zeros((n * n, n * n))
    np.add.at(gram, (idx[:, :, None], idx[:, None, :]), w[:, :, None] * w[:, None, :])
    order = np.argsort(idx.ravel(), kind="stable")
    texel, rows, weights = idx.ravel()[order], order // 4, w.ravel()[order]
    starts = np.flatnonzero(np.r_[True, texel[1:] != texel[:-1]])
    bt_c = np.zeros((n * n, len(dirs)))
    for s in range(0, len(dirs), 1024):  # B^T C by blocks of cube texels
        lobe = np.maximum(fit[rows] @ dirs[s:s + 1024].T, 0.0) * (sa[s:s + 1024] / np.pi)
        bt_c[texel[starts], s:s + 1024] = np.add.reduceat(weights[:, None] * lobe, starts, axis=0)
    out = np.linalg.solve(gram, bt_c).astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=8)
def visibility_matrix(face: int, n: int = VIS) -> np.ndarray:
    """(n^2, 6 face^2) float32: per octahedral texel, the normalised lobe max(0, d.w)^VIS_SHARPNESS over the cube's
    texels (solid angle weighted)."""
    dirs = face_directions(face).reshape(-1, 3)
    sa = np.broadcast_to(texel_solid_angles(face), (6, face, face)).reshape(-1)
    w = np.maximum(texel_directions(n).reshape(-1, 3) @ dirs.T, 0.0) ** VIS_SHARPNESS * sa
    w /= w.sum(1, keepdims=True)
    out = w.astype(np.float32)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=8)
def _radial(face: int) -> np.ndarray:
    """(6 face^2,) |direction| of each texel centre with forward part 1: distance = depth z x this."""
    s, t = face_st(face)
    return np.broadcast_to(np.sqrt(1.0 + s * s + t * t), (6, face, face)).reshape(-1)


def _shrink(a: np.ndarray, face: int) -> np.ndarray:
    """(P, 6, F, F, C) -> (P, 6, face, face, C) averaging F/face squared blocks, where F is a multiple of a smaller
    face (else as it is)."""
    f = a.shape[2]
    if f <= face or f % face:
        return a
    k = f // face
    p, _, _, _, c = a.shape
    return a.reshape(p, 6, face, k, face, k, c).mean((3, 5))


def maps_from_cubes(rgba: np.ndarray, depth: np.ndarray, far: float,
                    hole_colour=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cubes (P, 6, F, F, 4) premultiplied RGB + coverage and their depth (P, 6, F, F) -> (irradiance (P, IRR, IRR,
    3), moments (P, VIS, VIS, 2), hole fraction (P,)). The numpy stage after the render (volume_bench times it)."""
    p, _, f = rgba.shape[:3]
    sa = np.broadcast_to(texel_solid_angles(f), (6, f, f))
    alpha = rgba[..., 3]
    holes = np.clip(1.0 - alpha, 0.0, 1.0)
    hole_fraction = (holes * sa).reshape(p, -1).sum(1) / (4 * np.pi)
    rgb = rgba[..., :3] + holes[..., None] * np.asarray(hole_colour, np.float32)
    r = np.where(alpha >= COVERED, depth * _radial(f).reshape(6, f, f), far).astype(np.float32)[..., None]
    r = np.concatenate([r, r * r], -1)  # the moments' two samples, averaged apart where the faces shrink
    rgb, r = _shrink(rgb, IRR_FACE), _shrink(r, VIS_FACE)
    gi, gv = rgb.shape[2], r.shape[2]
    irr = (irradiance_matrix(gi) @ rgb.reshape(p, -1, 3).transpose(1, 0, 2).reshape(6 * gi * gi, -1))
    irr = irr.reshape(IRR, IRR, p, 3)
    mom = visibility_matrix(gv) @ r.reshape(p, -1, 2).transpose(1, 0, 2).reshape(6 * gv * gv, -1)
    mom = mom.reshape(VIS, VIS, p, 2).transpose(2, 0, 1, 3)
    return irr.transpose(2, 0, 1, 3).astype(np.float64), mom.astype(np.float64), hole_fraction


def closeness(rgba: np.ndarray, depth: np.ndarray, near: float) -> np.ndarray:
    """(P,) the share of each probe's sphere covered by splats nearer than ``near`` (the inside test's; cubes as
    maps_from_cubes takes them)."""
    f = rgba.shape[2]
    close = (rgba[..., 3] >= COVERED) & (depth * _radial(f).reshape(6, f, f) < near)
    return (close * texel_solid_angles(f)).reshape(len(rgba), -1).sum(1) / (4 * np.pi)


def probes_per_submission(renderer, probes: int, face: int) -> int:
    """How many probes one render with depth takes: one group of the device, and a frame that fits."""
    from ..render.renderer import largest_probe_face, probes_per_group
    chunk = probes_per_group(renderer.ctx, renderer.nodes, probes, renderer.lod is not None)
    while chunk > 1 and largest_probe_face(renderer.ctx, chunk) < face:
        chunk = (chunk + 1) // 2
    return max(1, chunk)


def far_distance(spec: GridSpec) -> float:
    return FAR_FACTOR * (float(np.linalg.norm(np.subtract(spec.hi, spec.lo))) + spec_spacing(spec))


def bake_probes(renderer, positions: np.ndarray, far: float, near: float, face_size: int = DEFAULT_FACE,
                progress: Callable[[int, int], None] | None = None, hole_colour=(0.0, 0.0, 0.0),
                inside_test: bool = True, lod_k: float = 0.0) -> dict:
    """Probes at (P, 3) ``positions`` -> {"irradiance" (P, IRR, IRR, 3), "moments" (P, VIS, VIS, 2) (zero for a probe
    inside an object: splats within ``near`` metres over INSIDE_FRACTION of its sphere), "holes" (P,), "inside"
    (P,), "render_ms", "maps_ms", "per_submission", "gpu_maps"}; ``far``: the distance of a direction with no
    splats. Faces up to VIS_FACE make their maps on the GPU where GPU_MAPS says, larger ones in numpy
    (maps_from_cubes)."""
    from ..render.views import ViewBatch
    from .gpu_volume_maps import volume_maps
    face = int(face_size)
    if face < 4 or face & (face - 1):
        raise ValueError(f"face size {face_size} must be a power of two, 4 or more")
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    n = len(pos)
    chunk = probes_per_submission(renderer, max(n, 1), face)
    irr = np.empty((n, IRR, IRR, 3))
    mom = np.empty((n, VIS, VIS, 2))
    holes = np.empty(n)
    inside = np.zeros(n, bool)
    t_render = t_maps = 0.0
    use_gpu = not renderer.ctx.is_cpu if GPU_MAPS is None else GPU_MAPS
    on_gpu = use_gpu and face <= VIS_FACE  # visibility keeps the frame's texels there (no box-average)
    for start in range(0, n, chunk):
        t0 = time.perf_counter()
        part = pos[start:start + chunk]
        sl = slice(start, start + len(part))
        res = renderer.render(ViewBatch.cubemaps(part, face), depth=True, lod_k=lod_k, wait=not on_gpu)
        if on_gpu:  # the maps and both fractions made behind the render, read back small
            t1 = time.perf_counter()
            irr[sl], mom[sl], holes[sl], close = volume_maps(res.frame, irradiance_matrix(min(face, IRR_FACE)),
                                                              visibility_matrix(face), far, near, hole_colour)
        else:
            rgba = res.frame.read_probes()
            depth = res.frame.depth.read(np.float32, len(part) * 6 * face * face).reshape(len(part), 6, face, face)
            t1 = time.perf_counter()
            irr[sl], mom[sl], holes[sl] = maps_from_cubes(rgba, depth, far, hole_colour)
            close = closeness(rgba, depth, near) if inside_test else None
        if inside_test:
            inside[sl] = close > INSIDE_FRACTION
        t_render += t1 - t0
        t_maps += time.perf_counter() - t1
        if progress is not None:
            progress(start + len(part), n)
    mom[inside] = 0.0
    return {"irradiance": irr, "moments": mom, "holes": holes, "inside": inside, "render_ms": 1e3 * t_render,
            "maps_ms": 1e3 * t_maps, "per_submission": chunk, "gpu_maps": on_gpu}


def probe_report(holes: np.ndarray, inside: np.ndarray, hole_colour=(0.0, 0.0, 0.0)) -> list[str]:
    """The user's lines about probes inside objects and probes that see holes."""
    n, report = len(holes), []
    if inside.any():
        report.append(f"{int(inside.sum())} of {n} probes are inside splat objects: left out of the lookup")
    if (holes > HOLE_REPORT).any():
        report.append(f"{int((holes > HOLE_REPORT).sum())} of {n} probes see holes (up to "
                      f"{100 * holes.max():.0f}% of their sphere has no splats): filled with "
                      f"{tuple(map(float, hole_colour))}")
    return report


def bake_volume(renderer, spec: GridSpec, face_size: int = DEFAULT_FACE,
                progress: Callable[[int, int], None] | None = None, hole_colour=(0.0, 0.0, 0.0),
                inside_test: bool = True, lod_k: float = 0.0) -> LightVolume:
    """The light volume of the splats ``renderer`` holds (world space), probes on ``spec`` (no bricks:
    volume_refine.bake_refined adds them); ``face_size``^2 cube faces; ``progress(done, total)`` after each
    submission; ``lod_k`` > 0 (a renderer built with a level of detail): merged splats where a probe's pixel allows
    (SplatRenderer.render's). Timings (ms): render (GPU and read-back), maps (numpy, or the GPU's maps and
    their read-back: bake_probes)."""
    b = bake_probes(renderer, probe_positions(spec), far_distance(spec), 0.5 * spec_spacing(spec), face_size,
                    progress, hole_colour, inside_test, lod_k)
    n = spec.count
    return LightVolume(spec, grid_maps(b["irradiance"], spec.shape), grid_maps(b["moments"], spec.shape),
                       timings={"render": b["render_ms"], "maps": b["maps_ms"], "probes": n, "face": int(face_size),
                                "per_submission": b["per_submission"], "lod_k": float(lod_k)},
                       report=probe_report(b["holes"], b["inside"], hole_colour))


def point_irradiance(renderer, points: np.ndarray, normals: np.ndarray, face_size: int = 32,
                     chunk: int = 24) -> np.ndarray:
    """The reference a volume is measured against: E/pi (M, 3) at each point from its own cube (``face_size``^2,
    every splat), the exact cosine integral of its texels at the point's unit normal."""
    w = face_directions(face_size).reshape(-1, 3)
    sa = np.broadcast_to(texel_solid_angles(face_size), (6, face_size, face_size)).reshape(-1)
    pts, nrm = np.asarray(points, np.float64).reshape(-1, 3), np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.empty((len(pts), 3))
    for s in range(0, len(pts), chunk):
        cubes = renderer.render_probes(pts[s:s + chunk], face_size).frame.read_probes()[..., :3]
        lobe = np.maximum(nrm[s:s + chunk] @ w.T, 0.0) * sa / np.pi
        out[s:s + chunk] = np.einsum("pk,pkc->pc", lobe, cubes.reshape(len(lobe), -1, 3).astype(np.float64))
    return out

