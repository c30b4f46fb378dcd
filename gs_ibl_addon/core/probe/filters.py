"""One call from a radiance cube to a ProbeResult with the chosen irradiance method, timed.

``use_gpu=False`` runs the numpy implementations (the references). ``use_gpu=True`` runs every stage that has a
Vulkan version on the GPU as one recorded program (gpu_filters.FilterPlan: SH order 2 projection, cosine
convolution, box, exact; SH evaluation; GGX prefiltered maps); SH of another order stays in numpy. The radiance
may be a numpy cube (uploaded once into a pooled buffer) or a GpuFrame from the renderer: then nothing crosses to
the host but the SH/hole partials, the irradiance and, when ``read_radiance``, the radiance the caller writes.
Timings are in milliseconds: GPU stages report GPU timestamps (``timings_ms['irradiance']`` = the filter's GPU
time, with per-stage detail under ``irradiance.<stage>``), numpy stages wall time; ``settings['stage_devices']``
says which ran where.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .box import box_irradiance
from .convolve import cosine_convolve
from .ggx import DEFAULT_ROUGHNESS, ggx_prefilter
from .reference import exact_irradiance_cube
from .result import ProbeResult
from .sampling import split_alpha
from .sh_project import project_cube, sh_irradiance_faces
from ..settings import DEFAULT_DOWNSAMPLE_TO, FILTER_METHODS as METHODS


@dataclass(frozen=True, kw_only=True)
class _Params:
    """What the irradiance and GGX stages are asked for (filter_probe's arguments, minus where they run)."""
    size: int
    method: str
    sh_order: int
    sh_window: str
    phi_steps: int
    theta_steps: int
    box_level_size: int
    downsample_to: int | None
    roughness: tuple[float, ...] | None
    ggx_samples: int


class _Stages:
    """Runs filter stages, recording each one's time (ms) under its name and where it ran (cpu/gpu)."""

    def __init__(self, timings: dict[str, float]) -> None:
        self.timings = timings
        self.devices: dict[str, str] = {}

    def cpu(self, name: str, fn, *args, **kw):
        t0 = time.perf_counter()
        out = fn(*args, **kw)
        self.timings[name] = (time.perf_counter() - t0) * 1e3
        self.devices[name] = "cpu"
        return out

    def gpu(self, name: str, fn, *args, **kw):
        """fn returns (result, GPU timings): the stage's time is the GPU's where the device has timestamps."""
        t0 = time.perf_counter()
        out, tm = fn(*args, **kw)
        wall = (time.perf_counter() - t0) * 1e3
        self.timings[name] = tm.get("total", wall)
        self.timings[f"{name}_wall"] = wall
        self.timings.update({f"{name}.{k}": v for k, v in tm.items() if k != "total"})
        self.devices[name] = "gpu"
        return out


def _is_frame(obj) -> bool:
    return hasattr(obj, "image") and hasattr(obj, "batch")  # render.renderer.GpuFrame


def filter_probe(radiance, irradiance_size: int = 16, method: str = "sh", sh_order: int = 2,
                 sh_window: str = "none", phi_steps: int = 64, theta_steps: int = 16, box_level_size: int = 1,
                 downsample_to: int | None = DEFAULT_DOWNSAMPLE_TO,
                 roughness: tuple[float, ...] | None = DEFAULT_ROUGHNESS, ggx_samples: int = 256,
                 use_gpu: bool = False, vk_context=None, read_radiance: bool = True,
                 **result_fields: Any) -> ProbeResult:
    """Filter a (6, N, N, 3|4) radiance cube, or a renderer's GpuFrame (always on the GPU); SH coefficients are
    always computed (cheap, and stored in probe.json).

    roughness=None skips the GGX maps. downsample_to (exact method) halves the faces down to that size before
    integrating (None: every texel). vk_context: the Vulkan context for use_gpu with a numpy cube (default: the
    shared one; a frame brings its renderer's). read_radiance=False leaves a frame's radiance on the GPU
    (ProbeResult.radiance is then None: a face-size search step needs only the irradiance).
    Extra keyword arguments (splat_count, device, timings_ms, settings, ...) go to the ProbeResult.
    """
    if method not in METHODS:
        raise ValueError(f"irradiance method must be one of {METHODS}, got {method!r}")
    stages = _Stages(dict(result_fields.pop("timings_ms", {})))
    p = _Params(size=irradiance_size, method=method, sh_order=sh_order, sh_window=sh_window, phi_steps=phi_steps,
                theta_steps=theta_steps, box_level_size=box_level_size, downsample_to=downsample_to,
                roughness=None if roughness is None else tuple(roughness), ggx_samples=ggx_samples)
    frame = radiance if _is_frame(radiance) else None
    if frame is not None and sh_order != 2:  # numpy SH of another order needs the cube on the host
        radiance, frame = frame.read_cube(), None
    if frame is not None:
        coeffs, irr, pre, hole = _filter_gpu(frame, p, frame.ctx, stages)
        face = frame.face_size
        radiance = frame.read_cube() if read_radiance else None
        use_gpu = True
    else:
        rgb, hole = split_alpha(radiance)
        face = int(rgb.shape[1])
        if use_gpu:
            coeffs, irr, pre, _ = _filter_gpu(rgb, p, vk_context, stages)
        else:
            coeffs, irr, pre = _filter_cpu(rgb, p, stages)
        radiance = np.asarray(radiance)
    settings = {"method": method, "irradiance_size": irradiance_size, "sh_order": sh_order, "sh_window": sh_window,
                "phi_steps": phi_steps, "theta_steps": theta_steps, "box_level_size": box_level_size,
                "downsample_to": downsample_to, "ggx_samples": ggx_samples, "radiance_face_size": face,
                "use_gpu": bool(use_gpu), "stage_devices": stages.devices}
    settings.update(result_fields.pop("settings", {}))
    return ProbeResult(radiance=radiance, irradiance=irr, sh_coefficients=coeffs, prefiltered=pre,
                       roughness=[] if roughness is None else list(roughness), settings=settings,
                       timings_ms=stages.timings, hole_fraction=hole, **result_fields)


def _filter_cpu(rgb: np.ndarray, p: _Params, stages: _Stages) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    coeffs = stages.cpu("sh_project", project_cube, rgb, p.sh_order)
    if p.method == "sh":
        irr = stages.cpu("irradiance", sh_irradiance_faces, coeffs, p.size, p.sh_window)
    elif p.method == "convolve":
        irr = stages.cpu("irradiance", cosine_convolve, rgb, p.size, p.phi_steps, p.theta_steps)
    elif p.method == "box":
        irr = stages.cpu("irradiance", box_irradiance, rgb, p.size, p.box_level_size)
    else:
        irr = stages.cpu("irradiance", exact_irradiance_cube, rgb, p.size, p.downsample_to)
    pre = [] if p.roughness is None else stages.cpu("ggx", ggx_prefilter, rgb, p.roughness, None, p.ggx_samples)
    return coeffs, irr, pre


def _filter_gpu(source, p: _Params, ctx, stages: _Stages
                ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], float]:
    """source: an RGB numpy cube or a GpuFrame. Returns (coeffs, irradiance, GGX cubes, hole fraction of a frame)."""
    from . import gpu_filters as g  # Vulkan is imported only when the GPU path is asked for

    frame = source if _is_frame(source) else None
    ctx = frame.ctx if frame is not None else (ctx or g.get_context())
    if p.sh_order != 2:  # numpy SH of another order; the rest still on the GPU, from one upload
        with g.upload_cube(source, ctx) as cube:
            coeffs = stages.cpu("sh_project", project_cube, source, p.sh_order)
            irr = stages.cpu("irradiance", sh_irradiance_faces, coeffs, p.size, p.sh_window) \
                if p.method == "sh" else _irradiance_gpu(g, cube, p, stages)
            pre = [] if p.roughness is None else stages.gpu("ggx", g.gpu_ggx_prefilter, cube, p.roughness, None,
                                                              p.ggx_samples)
        return coeffs, irr, pre, 0.0
    t0 = time.perf_counter()
    if frame is not None:
        src, n = frame.image, frame.face_size
        frame.check()
    else:
        n = int(source.shape[1])
        src = g.scratch(ctx, 6 * n * n * 12, "probe-radiance")
        src.write(np.ascontiguousarray(source, np.float32))
        stages.timings["upload"] = (time.perf_counter() - t0) * 1e3
    try:
        plan = g.plan_for(ctx, src, frame is not None, n, p.method, p.size, phi_steps=p.phi_steps,
                          theta_steps=p.theta_steps, box_level_size=p.box_level_size, downsample_to=p.downsample_to)
        t1 = time.perf_counter()
        if frame is not None:  # queued behind the render (if still in flight): the host waits once for both
            plan.program.start()
            if frame.wait():  # the render was drawn again after this filter was queued: filter it again
                plan.program.wait()
            coeffs, irr, hole, tm = plan.finish()
        else:
            coeffs, irr, hole, tm = plan.run()
        wall = (time.perf_counter() - t1) * 1e3
        pre_stages = {"split", "sh_project"}
        stages.timings["sh_project"] = sum(v for k, v in tm.items() if k in pre_stages)
        stages.devices["sh_project"] = "gpu"
        if p.method == "sh":
            irr = stages.gpu("irradiance", g.gpu_sh_irradiance, coeffs, p.size, p.sh_window, ctx=ctx)
        else:
            rest = {k: v for k, v in tm.items() if k not in pre_stages and k != "total"}
            stages.timings["irradiance"] = sum(rest.values()) if rest else wall
            stages.timings.update({f"irradiance.{k}": v for k, v in rest.items()})
            stages.devices["irradiance"] = "gpu"
        stages.timings["filter_gpu"] = tm.get("total", wall)
        stages.timings["filter_wall"] = wall  # host time to the results: includes a queued render still running
        pre = ([] if p.roughness is None
               else stages.gpu("ggx", g.gpu_ggx_prefilter, frame if frame is not None else _cube_of(g, src, n, ctx),
                               p.roughness, None, p.ggx_samples))
    finally:
        if frame is None:
            src.close()
    return coeffs, irr, pre, hole


def _cube_of(g, buf, n: int, ctx):
    """A GpuCube view of an uploaded RGB buffer (no copy; the caller keeps the buffer)."""
    cube = g.GpuCube.__new__(g.GpuCube)
    cube.ctx, cube.size, cube.buffer, cube.hole_fraction = ctx, n, buf, 0.0
    return cube


def _irradiance_gpu(g, cube, p: _Params, stages: _Stages) -> np.ndarray:
    if p.method == "convolve":
        return stages.gpu("irradiance", g.gpu_cosine_convolve, cube, p.size, p.phi_steps, p.theta_steps)
    if p.method == "box":
        return stages.gpu("irradiance", g.gpu_box_irradiance, cube, p.size, p.box_level_size)
    return stages.gpu("irradiance", g.gpu_exact_irradiance, cube, p.size, p.downsample_to)
