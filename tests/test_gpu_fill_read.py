"""fill_frame_holes(..., read=True) (core/probe/gpu_holes.py): the filled cubes read back in the fill's own program,
through a host-visible copy where the frame's memory is not host-cached (a discrete GPU; here its flag is turned off
so lavapipe takes that path), equal the frame read after the fill."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core.probe.gpu_filters import filter_probes
from gs_ibl_addon.core.probe.gpu_holes import fill_frame_holes
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.synthetic import random_scene


@pytest.mark.parametrize("cached", [True, False])
def test_the_filled_cubes_read_with_the_fill(monkeypatch, cached):
    with SplatRenderer(random_scene(1500, seed=11, sh_degree=1)) as r:
        frame = r.render_probes(np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.1]]), 16, wait=False).frame
        frame.wait()
        monkeypatch.setattr(frame.image, "host_cached", cached)
        before = r.ctx.stats.snapshot()
        with fill_frame_holes(frame, np.array([[0.2, 0.3, 0.4], [0.5, 0.1, 0.0]]), read=True) as filled:
            filter_probes(frame, 4, "sh")
        got = filled.read()
        submits = r.ctx.stats.since(before)["submits"]
        monkeypatch.setattr(frame.image, "host_cached", True)
        want = frame.read_probes()
    assert submits == 1  # the fill, its copy and the filter: one submission, the read none of its own
    assert got.shape == want.shape == (2, 6, 16, 16, 4)
    np.testing.assert_array_equal(got, want)
