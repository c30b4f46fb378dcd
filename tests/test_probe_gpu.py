"""GPU probe filters (Vulkan compute; lavapipe on CPU-only machines) against their numpy references.

Tolerance for every comparison: max |gpu - numpy| <= 2e-5 x max |numpy|. The GPU works in float32 (a texel
direction, a bilinear weight, a sum of up to 6*64^2 terms); measured worst 3.5e-6 (convolution of the
bright-patch cube), others ~2e-7. Anything beyond is a logic difference (a wrong face, tap or weight),
which shows up as errors of order 1e-2 and more.
"""
import numpy as np
import pytest

from gs_ibl_addon.core import cubemap
from gs_ibl_addon.core.probe import box_irradiance, cosine_convolve, project_cube, sh_irradiance
from gs_ibl_addon.core.probe.reference import bright_patch_environment, cube_from_function, smooth_environment
from gs_ibl_addon.core.vk import VulkanUnavailable, get_context

TOL = 2e-5


@pytest.fixture(scope="module")
def ctx():
    try:
        return get_context()
    except VulkanUnavailable as e:  # CI installs lavapipe, so this only skips on a machine without any Vulkan
        pytest.skip(str(e))


@pytest.fixture(scope="module")
def gpu():
    from gs_ibl_addon.core.probe import gpu_filters
    return gpu_filters


CUBES = {
    "smooth": lambda: cube_from_function(smooth_environment, 32),
    "patch": lambda: cube_from_function(bright_patch_environment, 32),
    "random": lambda: np.random.default_rng(5).random((6, 8, 8, 3)) * 10,  # every texel differs: edge/corner taps
}


def close(gpu_val, ref):
    err = np.max(np.abs(gpu_val - ref)) / np.max(np.abs(ref))
    assert err <= TOL, f"relative max error {err:.3g} > {TOL}"


@pytest.mark.parametrize("name", sorted(CUBES))
def test_sh_projection(ctx, gpu, name):
    cube = CUBES[name]()
    coeffs, timings = gpu.gpu_sh_project(cube, ctx)
    close(coeffs, project_cube(cube, 2))
    assert "sh_project" in timings or not ctx.timestamps_supported


@pytest.mark.parametrize("window", ["none", "hanning"])
def test_sh_irradiance(ctx, gpu, window):
    coeffs = project_cube(CUBES["patch"](), 2)  # has negative lobes: the clamp is exercised
    for clamp in (True, False):
        irr, _ = gpu.gpu_sh_irradiance(coeffs, 8, window=window, clamp=clamp, ctx=ctx)
        close(irr, sh_irradiance(coeffs, cubemap.face_directions(8), window=window, clamp=clamp))


@pytest.mark.parametrize("name", sorted(CUBES))
def test_cosine_convolution(ctx, gpu, name):
    cube = CUBES[name]()
    irr, _ = gpu.gpu_cosine_convolve(cube, 8, 16, 4, ctx=ctx)
    close(irr, cosine_convolve(cube, 8, 16, 4))


@pytest.mark.parametrize("name", sorted(CUBES))
@pytest.mark.parametrize("level", [8, 2, 1])
def test_box_filter(ctx, gpu, name, level):
    cube = CUBES[name]()
    irr, _ = gpu.gpu_box_irradiance(cube, 8, level, ctx=ctx)
    close(irr, box_irradiance(cube, 8, level))


def test_alpha_holes_are_black_on_gpu(ctx, gpu):
    cube = np.concatenate([CUBES["smooth"](), np.ones((6, 32, 32, 1))], -1)
    cube[2] = 0.0  # +Y has no splats: premultiplied black
    coeffs, _ = gpu.gpu_sh_project(cube, ctx)
    close(coeffs, project_cube(cube[..., :3], 2))
