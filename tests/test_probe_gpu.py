"""GPU probe filters (Vulkan compute; lavapipe on CPU-only machines) against their numpy references.

Tolerance for every comparison: max |gpu - numpy| <= 2e-5 x max |numpy|. The GPU works in float32 (a texel
direction, a bilinear weight, a sum of up to 6*64^2 terms); measured worst 3.5e-6 (convolution of the
bright-patch cube), others ~2e-7 (exact integration: 2.6e-7; GGX prefilter: <= 9.5e-7, the roughness-0 level of the
bright-patch cube). Anything beyond is a logic difference (a wrong face, tap or weight), which shows up as errors
of order 1e-2 and more.
"""
import numpy as np
import pytest

from gs_ibl_addon.core import cubemap
from gs_ibl_addon.core.bake import relative_rms
from gs_ibl_addon.core.probe import (box_irradiance, cosine_convolve, exact_irradiance_cube, filter_probe,
                                     project_cube, sh_irradiance)
from gs_ibl_addon.core.probe.box import downsample_cube
from gs_ibl_addon.core.probe.ggx import ggx_prefilter
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


def check_timings(ctx, timings: dict, stages: tuple[str, ...]) -> None:
    """A filter reports GPU time per stage plus their total where the device has timestamp queries, else nothing
    (no wall-clock stand-in: filter_probe adds that and says so)."""
    if not ctx.timestamps_supported:
        assert timings == {}, timings
        return
    assert set(timings) == set(stages) | {"total"}, timings
    assert all(v >= 0 for v in timings.values()), timings
    assert abs(sum(timings[k] for k in stages) - timings["total"]) <= 1e-6 * max(1.0, timings["total"]), timings


@pytest.mark.parametrize("name", sorted(CUBES))
def test_sh_projection(ctx, gpu, name):
    cube = CUBES[name]()
    coeffs, timings = gpu.gpu_sh_project(cube, ctx)
    close(coeffs, project_cube(cube, 2))
    check_timings(ctx, timings, ("sh_project",))


@pytest.mark.parametrize("window", ["none", "hanning"])
def test_sh_irradiance(ctx, gpu, window):
    coeffs = project_cube(CUBES["patch"](), 2)  # has negative lobes: the clamp is exercised
    for clamp in (True, False):
        irr, timings = gpu.gpu_sh_irradiance(coeffs, 8, window=window, clamp=clamp, ctx=ctx)
        close(irr, sh_irradiance(coeffs, cubemap.face_directions(8), window=window, clamp=clamp))
        check_timings(ctx, timings, ("sh_irradiance",))


@pytest.mark.parametrize("name", sorted(CUBES))
def test_cosine_convolution(ctx, gpu, name):
    cube = CUBES[name]()
    irr, timings = gpu.gpu_cosine_convolve(cube, 8, 16, 4, ctx=ctx)
    close(irr, cosine_convolve(cube, 8, 16, 4))
    check_timings(ctx, timings, ("convolve",))


@pytest.mark.parametrize("name", sorted(CUBES))
@pytest.mark.parametrize("level", [8, 2, 1])
def test_box_filter(ctx, gpu, name, level):
    cube = CUBES[name]()
    irr, timings = gpu.gpu_box_irradiance(cube, 8, level, ctx=ctx)
    close(irr, box_irradiance(cube, 8, level))
    check_timings(ctx, timings, ("downsample", "read"))


def test_alpha_holes_are_black_on_gpu(ctx, gpu):
    cube = np.concatenate([CUBES["smooth"](), np.ones((6, 32, 32, 1))], -1)
    cube[2] = 0.0  # +Y has no splats: premultiplied black
    coeffs, _ = gpu.gpu_sh_project(cube, ctx)
    close(coeffs, project_cube(cube[..., :3], 2))


@pytest.mark.parametrize("name", sorted(CUBES))
@pytest.mark.parametrize("downsample_to", [None, 16, 4])
def test_exact_integration(ctx, gpu, name, downsample_to):
    # GPU: one workgroup per normal summing every texel of the (downsampled) cube; numpy: float64 matrix product.
    cube = CUBES[name]()
    irr, timings = gpu.gpu_exact_irradiance(cube, 8, downsample_to, ctx=ctx)
    close(irr, exact_irradiance_cube(cube, 8, downsample_to))
    check_timings(ctx, timings, ("downsample", "integrate"))


def test_exact_downsampling_loss_is_small():
    # Irradiance is a low-pass: integrating a power-preserving box-downsampled copy only moves the cosine from
    # child to parent texel centres. Measured rel RMS vs all 64^2 texels (M=16 normals): smooth environment
    # 3.5e-5 (32), 1.7e-4 (16), 7.5e-4 (8); 1000:1 bright disc 2.4e-4 (32), 1.1e-3 (16), 7.8e-3 (8), 0.13 (4).
    # Bounds: 2x measured; and the loss must grow as the faces shrink (the test can fail).
    for fn, bounds in ((smooth_environment, {32: 7e-5, 16: 3.4e-4, 8: 1.5e-3}),
                       (bright_patch_environment, {32: 5e-4, 16: 2.2e-3, 8: 1.6e-2})):
        cube = cube_from_function(fn, 64)
        full = exact_irradiance_cube(cube, 16)
        errs = {k: relative_rms(exact_irradiance_cube(cube, 16, k), full) for k in bounds}
        assert all(errs[k] < b for k, b in bounds.items()), errs
        assert errs[32] < errs[16] < errs[8]


def test_exact_rejects_bad_downsample(ctx, gpu):
    with pytest.raises(ValueError, match="downsample_to"):
        gpu.gpu_exact_irradiance(CUBES["random"](), 4, 0, ctx=ctx)
    with pytest.raises(ValueError, match="downsample_to"):
        exact_irradiance_cube(CUBES["random"](), 4, 0)


def test_gpu_and_numpy_refuse_the_same_arguments_alike(ctx, gpu):
    # One validating function per argument kind, called by both paths: the same ValueError, word for word.
    cube = CUBES["random"]()  # 8^2 faces
    cases = [
        ("level size 3 must be the face size 8 divided by a power of 2",
         lambda: box_irradiance(cube, 8, 3), lambda: gpu.gpu_box_irradiance(cube, 8, 3, ctx=ctx)),
        ("at least one step per angle, got phi=0 theta=4",
         lambda: cosine_convolve(cube, 4, 0, 4), lambda: gpu.gpu_cosine_convolve(cube, 4, 0, 4, ctx=ctx)),
        ("2 roughness levels but 1 sizes",
         lambda: ggx_prefilter(cube, (0.0, 0.5), (4,)), lambda: gpu.gpu_ggx_prefilter(cube, (0.0, 0.5), (4,), ctx=ctx)),
        ("needs samples >= 1 and face sizes >= 1, got 0",
         lambda: ggx_prefilter(cube, (0.5,), (4,), 0), lambda: gpu.gpu_ggx_prefilter(cube, (0.5,), (4,), 0, ctx=ctx)),
        ("downsample_to must be >= 1 or None, got 0",
         lambda: exact_irradiance_cube(cube, 4, 0), lambda: gpu.gpu_exact_irradiance(cube, 4, 0, ctx=ctx)),
    ]
    for words, numpy_call, gpu_call in cases:
        with pytest.raises(ValueError) as a:
            numpy_call()
        with pytest.raises(ValueError) as b:
            gpu_call()
        assert words in str(a.value) and str(a.value) == str(b.value), (str(a.value), str(b.value))


@pytest.mark.parametrize("method", ["sh", "convolve", "box", "exact"])
def test_filter_probe_on_gpu_matches_numpy(ctx, method):
    # The bake calls filter_probe(..., use_gpu=True) with its extra settings; the same call on numpy must agree.
    cube = np.concatenate([CUBES["patch"](), np.ones((6, 32, 32, 1))], -1)
    cube[1, :4, :4, 3] = 0.0  # a hole: reported the same way on both paths
    kw = dict(irradiance_size=8, method=method, roughness=None, phi_steps=16, theta_steps=4, box_level_size=2,
              downsample_to=16, sh_window="hanning", timings_ms={"render_total": 1.0}, settings={"lead": "x"},
              splat_count=7, device="dev")
    a = filter_probe(cube, use_gpu=True, vk_context=ctx, **kw)
    b = filter_probe(cube, use_gpu=False, **kw)
    close(a.irradiance, b.irradiance)
    close(a.sh_coefficients, b.sh_coefficients)
    assert a.hole_fraction == b.hole_fraction > 0
    assert a.settings["stage_devices"] == {"sh_project": "gpu", "irradiance": "gpu"}
    assert b.settings["stage_devices"] == {"sh_project": "cpu", "irradiance": "cpu"}
    assert a.settings["lead"] == "x" and a.splat_count == 7 and a.device == "dev"
    assert a.timings_ms["render_total"] == 1.0 and a.timings_ms["irradiance"] > 0


def test_filter_probe_gpu_falls_back_to_numpy_for_other_sh_orders(ctx):
    cube = CUBES["smooth"]()
    a = filter_probe(cube, 8, "sh", sh_order=3, roughness=None, use_gpu=True, vk_context=ctx)
    np.testing.assert_allclose(a.irradiance, filter_probe(cube, 8, "sh", sh_order=3, roughness=None).irradiance)
    assert a.sh_coefficients.shape == (16, 3) and a.settings["stage_devices"]["irradiance"] == "cpu"


def test_uploaded_cube_serves_several_filters(ctx, gpu):
    cube = CUBES["patch"]()
    up = gpu.upload_cube(cube, ctx)
    try:
        close(gpu.gpu_exact_irradiance(up, 8, 8)[0], exact_irradiance_cube(cube, 8, 8))
        close(gpu.gpu_box_irradiance(up, 8, 4)[0], box_irradiance(cube, 8, 4))
        close(gpu.gpu_sh_project(up)[0], project_cube(cube, 2))
        glossy, _ = gpu.gpu_ggx_prefilter(up, (0.0, 0.5), (8, 4), 32)
        for a, b in zip(glossy, ggx_prefilter(cube, (0.0, 0.5), (8, 4), 32)):
            close(a, b)
    finally:
        up.close()


@pytest.mark.parametrize("name,samples", [("random", 256), ("random", 64), ("patch", 64), ("smooth", 64)])
def test_ggx_prefilter(ctx, gpu, name, samples):
    # Default roughness levels and sizes (32^2 cubes: 32, 16, 8, 4, 4; the 8^2 random one: 8, 4, 4, 4, 4). Both
    # paths use ggx.ggx_samples' table, so they differ only by float32 arithmetic in the shader.
    cube = CUBES[name]()
    out, timings = gpu.gpu_ggx_prefilter(cube, samples=samples, ctx=ctx)
    ref = ggx_prefilter(cube, samples=samples)
    assert [o.shape for o in out] == [r.shape for r in ref]
    for a, b in zip(out, ref):
        close(a, b)
    check_timings(ctx, timings, ("mips", "ggx"))


def test_ggx_prefilter_odd_chain_sizes_and_bias(ctx, gpu):
    # A 12^2 cube's chain stops at 3^2 (three mips); explicit sizes that are not powers of two; lod bias -100
    # (no mip filtering: every read at lod 0) and +3 (reads clamped at the last mip).
    cube = np.random.default_rng(7).random((6, 12, 12, 3)) * 5
    for bias in (-100.0, 1.0, 3.0):
        out, _ = gpu.gpu_ggx_prefilter(cube, (0.0, 0.3, 1.0), (5, 12, 3), 48, bias, ctx=ctx)
        for a, b in zip(out, ggx_prefilter(cube, (0.0, 0.3, 1.0), (5, 12, 3), 48, bias)):
            close(a, b)


@pytest.mark.parametrize("name", ["random", "patch"])
def test_ggx_roughness_zero_is_the_radiance(ctx, gpu, name):
    # Roughness 0 reads the radiance at the output's mip: the cube itself at full size, its box-downsampled copy
    # at half size. Roughness 1e-3 is a lobe 1e-3 degrees wide read at lod 0: within 1e-4 of the cube (numpy gives
    # the same 4.3e-5 on the patch's sharp edge).
    cube = CUBES[name]()
    n = cube.shape[1]
    same, half, tiny = gpu.gpu_ggx_prefilter(cube, (0.0, 0.0, 1e-3), (n, n // 2, n), 64, ctx=ctx)[0]
    close(same, cube)
    close(half, downsample_cube(cube))
    assert np.max(np.abs(tiny - cube)) <= 1e-4 * np.max(np.abs(cube))


def test_ggx_rejects_bad_sizes(ctx, gpu):
    with pytest.raises(ValueError, match="2 roughness levels but 1 sizes"):
        gpu.gpu_ggx_prefilter(CUBES["random"](), (0.0, 0.5), (4,), ctx=ctx)
    with pytest.raises(ValueError, match="samples"):
        gpu.gpu_ggx_prefilter(CUBES["random"](), (0.5,), (4,), 0, ctx=ctx)


def test_filter_probe_runs_ggx_on_gpu(ctx):
    cube = np.concatenate([CUBES["patch"](), np.ones((6, 32, 32, 1))], -1)
    cube[4, 10:20, 10:20] = 0.0  # a hole (premultiplied: black, alpha 0), the same on both paths
    kw = dict(irradiance_size=4, method="box", box_level_size=4, roughness=(0.0, 0.4, 1.0), ggx_samples=32)
    a = filter_probe(cube, use_gpu=True, vk_context=ctx, **kw)
    b = filter_probe(cube, use_gpu=False, **kw)
    assert [p.shape for p in a.prefiltered] == [(6, 32, 32, 3), (6, 16, 16, 3), (6, 8, 8, 3)]
    for x, y in zip(a.prefiltered, b.prefiltered):
        close(x, y)
    assert a.roughness == b.roughness == [0.0, 0.4, 1.0]
    assert a.settings["stage_devices"]["ggx"] == "gpu" and b.settings["stage_devices"]["ggx"] == "cpu"
    assert a.timings_ms["ggx"] > 0


@pytest.mark.parametrize("name,width,height", [("random", 64, None), ("patch", 128, 64), ("smooth", 50, 17)])
def test_cube_to_latlong(ctx, gpu, name, width, height):
    from gs_ibl_addon.core.probe import cube_to_latlong
    cube = CUBES[name]()
    out, timings = gpu.gpu_cube_to_latlong(cube, width, height, ctx=ctx)
    ref = cube_to_latlong(cube, width, height)
    assert out.shape == ref.shape
    close(out, ref)
    check_timings(ctx, timings, ("latlong",))
