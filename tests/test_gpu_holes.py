"""Holes filled on the GPU (core/probe/gpu_holes.py) against probe/holes.py's host fill: the covered mean from the
filter's SH and hole fraction, the filled frame texel by texel, and a batch bake that keeps only SH (a grid's
nodes) against the same bake filled on the host."""
from __future__ import annotations

import numpy as np

from gs_ibl_addon.core.bake import ProbeSettings
from gs_ibl_addon.core.bake_batch import bake_probes
from gs_ibl_addon.core.probe.gpu_filters import filter_probes
from gs_ibl_addon.core.probe.gpu_holes import covered_means, fill_frame_holes
from gs_ibl_addon.core.probe.holes import covered_mean, fill_holes
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.synthetic import random_scene

ORIGINS = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.1], [5.0, 5.0, 5.0]])  # the last one outside: mostly holes


def _scene():
    return random_scene(1500, seed=11, sh_degree=1)


def test_gpu_fill_equals_the_host_fill():
    with SplatRenderer(_scene()) as r:
        frame = r.render_probes(ORIGINS, 16, wait=False).frame
        f = filter_probes(frame, 4, "sh")
        cubes = frame.read_probes()
        assert np.all(f.hole_fraction > 0)
        want_means = np.stack([covered_mean(c) for c in cubes])
        means = covered_means(f.sh_coefficients, f.hole_fraction)
        np.testing.assert_allclose(means, want_means, rtol=1e-4, atol=1e-7)
        with fill_frame_holes(frame, means):
            pass
        got = frame.read_probes()
    for k, cube in enumerate(cubes):
        want, record = fill_holes(cube, "constant", means[k])
        np.testing.assert_allclose(got[k], want, rtol=0, atol=1e-6)
        assert abs(record["fraction"] - f.hole_fraction[k]) < 1e-5


def test_a_batch_fills_on_the_gpu_as_on_the_host(monkeypatch):
    from gs_ibl_addon.core import bake_batch
    s = ProbeSettings(method="sh", face_size=16, irradiance_size=4, hole_fill="mean")
    with SplatRenderer(_scene()) as r:
        with monkeypatch.context() as m:
            m.setattr(bake_batch, "GPU_FILLS", ())  # the host fill
            host = bake_probes(None, ORIGINS, s, renderer=r, keep_radiance=True)
        kept = bake_probes(None, ORIGINS, s, renderer=r, keep_radiance=True)  # filled on the GPU, then read
        for a, b in zip(kept, host):
            np.testing.assert_allclose(a.radiance, b.radiance, rtol=0, atol=1e-5 * np.abs(b.radiance).max())
        before = r.ctx.stats.snapshot()
        gpu = bake_probes(None, ORIGINS, s, renderer=r, keep_radiance=False)
        moved = r.ctx.stats.since(before)
    assert moved["readback_bytes"] < 16 * 6 * 16 * 16 * len(ORIGINS)  # no cube came back
    for a, b in zip(gpu, host):
        assert b.hole_fill["method"] == a.hole_fill["method"] == "mean"
        np.testing.assert_allclose(a.hole_fill["value"], b.hole_fill["value"], rtol=1e-4, atol=1e-7)
        assert abs(a.hole_fill["fraction"] - b.hole_fill["fraction"]) < 1e-5
        np.testing.assert_allclose(a.sh_coefficients, b.sh_coefficients, rtol=0,
                                   atol=1e-5 * np.abs(b.sh_coefficients).max())
        np.testing.assert_allclose(a.irradiance, b.irradiance, rtol=0, atol=1e-5 * np.abs(b.irradiance).max())


def test_a_probe_fills_on_the_gpu_as_on_the_host(monkeypatch):
    from gs_ibl_addon.core import bake
    from gs_ibl_addon.core.bake import bake_probe
    scene = _scene()
    for fill in ("mean", "constant"):
        s = ProbeSettings(face_size=16, irradiance_size=8, hole_fill=fill, hole_colour=(0.2, 0.3, 0.4),
                          glossy=True)
        with SplatRenderer(scene) as r:
            gpu = bake_probe(None, ORIGINS[1], s, renderer=r)
            with monkeypatch.context() as m:
                m.setattr(bake, "GPU_FILLS", ())  # the host fill
                host = bake_probe(None, ORIGINS[1], s, renderer=r)
        assert gpu.hole_fraction > 0 and gpu.hole_fill["method"] == host.hole_fill["method"] == fill
        np.testing.assert_allclose(gpu.hole_fill["value"], host.hole_fill["value"], rtol=1e-4, atol=1e-7)
        assert abs(gpu.hole_fill["fraction"] - host.hole_fill["fraction"]) < 1e-5
        for name in ("radiance", "irradiance", "sh_coefficients"):
            a, b = np.asarray(getattr(gpu, name)), np.asarray(getattr(host, name))
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-5 * np.abs(b).max(), err_msg=name)
        for a, b in zip(gpu.prefiltered, host.prefiltered):  # the glossy maps take the filled radiance
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-5 * np.abs(b).max())
