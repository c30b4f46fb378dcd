"""What the GPU benchmarks share: their scene, a warm-up, appending rows to a CSV, and kernels from a trial build."""
from __future__ import annotations

import contextlib
import csv
import os
import sys
import time
from typing import Callable

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from gs_ibl_addon.core.scene import SplatScene  # noqa: E402
from gs_ibl_addon.core.synthetic import random_scene  # noqa: E402


def bench_scene(n: int, sh_degree: int = 3, extent: float = 5.0) -> SplatScene:
    """random_scene filling a box around the origin. Trained captures are surfaces: more splats means smaller ones
    (size ~ 1/sqrt(count)), so overlap per pixel stays realistic instead of growing with the count; 50k splats
    keep random_scene's sizes."""
    scene = random_scene(n, seed=1, sh_degree=sh_degree, extent=extent)
    scene.scales *= min(1.0, (50_000 / n) ** 0.5)
    return scene


def shell_scene(n: int, seed: int = 7) -> SplatScene:
    """A random shell of radius 5-6 around the origin: isotropic splats of scale 0.02 * sqrt(1e6 / n), opacity 0.8,
    SH degree 3 (shared/tools/gpu_peer's second scene). Every splat is at about the same distance and most
    overlap many others: the opposite of bench_scene's volume for the sorts."""
    import numpy as np
    from gs_ibl_addon.core.scene import rgb_to_sh_dc
    rng = np.random.default_rng(seed)
    f32 = np.float32
    d = rng.standard_normal((n, 3), dtype=f32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pos = d * (f32(5.0) + rng.random(n, dtype=f32))[:, None]
    scales = np.full((n, 3), 0.02 * np.sqrt(1e6 / n), f32)
    rot = rng.standard_normal((n, 4), dtype=f32)
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    sh = rng.random((n, 16, 3), dtype=f32) - f32(0.5)
    band = np.array([0.96] + [2.0 * np.sqrt(3.0) * 0.15 / l for l in range(1, 4) for _ in range(2 * l + 1)], f32)
    sh *= band[:, None]
    sh[:, 0] = rgb_to_sh_dc(sh[:, 0] + f32(0.5))
    return SplatScene(pos, scales, rot, np.full(n, 0.8, f32), sh, source=f"<shell n={n} seed={seed}>")


def warm_up(step: Callable[[], object], seconds: float = 1.0) -> None:
    """Run ``step`` for a while: GPU clocks ramp after the idle seconds of building a scene on the CPU."""
    t = time.perf_counter()
    while time.perf_counter() - t < seconds:
        step()


def append_csv(path: str, rows: list[dict]) -> None:
    if not rows:
        return
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    new = not os.path.exists(path)
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        if new:
            w.writeheader()
        w.writerows(rows)


def hold_gpu_clock():
    """Open a CUDA context (torch) in this process: an NVIDIA GPU then holds its SM clock instead of falling to
    its idle clock under low-duty Vulkan work (shared/NOTES-vulkan-and-gpu.md). Returns the tensor that keeps the
    context alive, or None where torch or CUDA is missing."""
    try:
        import torch
        if not torch.cuda.is_available():
            return None
        return torch.zeros(1, device="cuda")
    except Exception:
        return None


def gpu_clock() -> int | str:
    """The SM clock (MHz) of NVIDIA GPU 0 by NVML now, or '' where NVML is missing."""
    try:
        import pynvml
        pynvml.nvmlInit()
        return int(pynvml.nvmlDeviceGetClockInfo(pynvml.nvmlDeviceGetHandleByIndex(0), pynvml.NVML_CLOCK_SM))
    except Exception:
        return ""


@contextlib.contextmanager
def kernels_from(folder: str | None):
    """Pipelines first made inside this block take each kernel with a NAME.spv in ``folder`` from there (a trial
    build: benchmarks/kernel_trials.py), the rest from the extension. Pipelines are made once per context, so a
    renderer on a context of its own keeps the trial's kernels after the block, beside others on the shared one."""
    from gs_ibl_addon.core.vk import pipelines
    load = pipelines._load_spirv
    if folder is None:
        yield
        return

    def trial(name: str) -> bytes:
        path = os.path.join(folder, name + ".spv")
        return open(path, "rb").read() if os.path.exists(path) else load(name)
    pipelines._load_spirv = trial
    try:
        yield
    finally:
        pipelines._load_spirv = load


def trial_dirs(folder: str | None) -> list[str]:
    """The trial builds under ``folder`` (benchmarks/kernel_trials.py build): its subfolders holding SPIR-V, by name."""
    if not folder:
        return []
    if not os.path.isdir(folder):
        raise SystemExit(f"--trials {folder}: no such folder (python benchmarks/kernel_trials.py build makes it)")
    subs = [os.path.join(folder, d) for d in sorted(os.listdir(folder))]
    return [d for d in subs if os.path.isdir(d) and any(f.endswith(".spv") for f in os.listdir(d))]
