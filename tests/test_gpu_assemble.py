"""The per-face search's cube put together on the GPU (core/probe/gpu_assemble.py GpuFaces, shaders/
probe_faces_to_size.comp) against the numpy reference (HostFaces: box.faces_to_size per face), kernel by kernel on
faces of random light (the faces' parts of the irradiance too: GpuFaces.parts against bake.irradiance_parts' numpy),
and a whole face size 0 bake of the lamp room that sizes its faces apart, against the same bake put together,
filled and filtered on the host (bake.GPU_ASSEMBLE off: the path before issue 38)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gs_ibl_addon.core import bake
from gs_ibl_addon.core.bake import ProbeSettings, bake_probe
from gs_ibl_addon.core.probe.gpu_assemble import GpuFaces, HostFaces, KeptCube
from gs_ibl_addon.core.probe.reference import exact_irradiance_parts
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.synthetic import sample_environment
from gs_ibl_addon.core.vk import Buffer, get_context

LAMP_AT = [0.0, 0.0, 1.0]  # tests/test_face_sizes.py's probe: the lamp straight above, in the +Z face


class _Frame:
    """A rendered frame as GpuFaces reads it: RGBA views one after another in a GPU buffer."""

    def __init__(self, ctx, images: list[np.ndarray]) -> None:
        data = np.concatenate([np.asarray(i, np.float32).reshape(-1) for i in images])
        self.ctx, self.image = ctx, Buffer(ctx, data.nbytes, "test-frame")
        self.image.write(data)
        self.face_size = images[0].shape[0]
        self.frame = self  # as a RenderResult

    def wait(self) -> bool:
        return False

    def check(self) -> None:
        pass


@pytest.mark.parametrize("start, rounds, out", [
    (64, [{4: 128}, {4: 256, 0: 128}], 128),  # the World probe's rounds: one face finer, then two
    (32, [{1: 128, 5: 64}], 128),  # two doublings at once (32 -> 128) beside one
    (64, [{2: 256}], 64),  # a cube smaller than its largest face
])
@pytest.mark.parametrize("parts_on", ["gpu", "host"])
def test_gpu_faces_equal_the_numpy_reference(start, rounds, out, parts_on):
    ctx = get_context()
    rng = np.random.default_rng(start + out)
    first = rng.random((6, 32, 32, 4)).astype(np.float32)
    last = rng.random((6, start, start, 4)).astype(np.float32)
    frames = [_Frame(ctx, list(first)), _Frame(ctx, list(last))]
    kept = [KeptCube(f, slot) for slot, f in enumerate(frames)]
    # the parts: on the GPU (the filter of six one-face cubes made there) or from the levels read back (a CPU device)
    gpu = GpuFaces(*kept, 32, 8, None if parts_on == "gpu" else exact_irradiance_parts)
    host = HostFaces(first, last, 32, 8, exact_irradiance_parts)
    try:
        for todo in [{}] + rounds:
            if todo:
                images = [rng.random((todo[f], todo[f], 4)).astype(np.float32) for f in sorted(todo)]
                drawn = _Frame(ctx, images)
                frames.append(drawn)
                host.put(SimpleNamespace(images=images), todo, out)
                gpu.put(drawn, todo, out)
                got = gpu.cube.read_cube()
                assert got.shape == host.cube.shape == (6, out, out, 4)
                np.testing.assert_allclose(got, host.cube, rtol=0, atol=2e-6)  # values in [0, 1): float32 sums
                assert gpu.sizes == host.sizes
            want = host.parts()
            assert want.shape == (6, 6, 8, 8, 3)
            # the filter's float32 sums against numpy's float64 (tests/test_bake_stages.py: 1e-6), here of a change
            # taken between float32 levels on the GPU (numpy's levels are float64): 1.2e-6 seen, 2e-6 allowed
            np.testing.assert_allclose(gpu.parts(), want, rtol=0, atol=2e-6 * np.abs(want).max())
    finally:
        gpu.close()
        for k in kept:
            k.close()
        for f in frames:
            f.image.destroy()


@pytest.mark.parametrize("parts_on_gpu", [True, False])
def test_a_per_face_bake_is_the_one_put_together_on_the_host(monkeypatch, parts_on_gpu):
    scene = sample_environment()
    scene = scene.subset(np.random.default_rng(3).permutation(scene.count))
    s = ProbeSettings(tolerance=0.01, irradiance_size=8, max_face_size=256, glossy=True)
    with SplatRenderer(scene) as r:
        with monkeypatch.context() as m:  # the parts as a GPU takes them (a filter queued with the faces' work)
            m.setattr(bake, "parts_on_gpu", lambda ctx: parts_on_gpu)
            gpu = bake_probe(None, LAMP_AT, s, renderer=r, host_splats=scene)
        with monkeypatch.context() as m:
            m.setattr(bake, "GPU_ASSEMBLE", False)
            host = bake_probe(None, LAMP_AT, s, renderer=r, host_splats=scene)
    sizes = gpu.settings["face_sizes"]
    assert sizes == host.settings["face_sizes"] and len(set(sizes)) > 1, sizes  # the faces were sized apart
    assert gpu.settings["face_size"] == host.settings["face_size"] == min(max(sizes), bake.RADIANCE_OUT_MAX)
    assert gpu.hole_fill["method"] == host.hole_fill["method"]
    np.testing.assert_allclose(gpu.hole_fill["value"], host.hole_fill["value"], rtol=1e-4, atol=1e-7)
    assert abs(gpu.hole_fill["fraction"] - host.hole_fill["fraction"]) < 1e-5
    # the tolerances of the GPU hole fill against the host's (tests/test_gpu_holes.py)
    for name in ("radiance", "irradiance", "sh_coefficients"):
        a, b = np.asarray(getattr(gpu, name)), np.asarray(getattr(host, name))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-5 * np.abs(b).max(), err_msg=name)
    for a, b in zip(gpu.prefiltered, host.prefiltered):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-5 * np.abs(b).max())
    est = [t.get("estimate") for t in gpu.settings["face_size_trials"]]
    np.testing.assert_allclose(est[1:], [t.get("estimate") for t in host.settings["face_size_trials"]][1:],
                               rtol=1e-4)
