"""A renderer sizes each batch shape's sort and emit for what that shape drew (SplatRenderer._caps), not for the
largest frame it ever drew: a small face after a large one sorts its own instances. Frames that outgrow their
shape's budget are drawn again, exactly as a fresh renderer draws them."""
import numpy as np
import pytest

from gs_ibl_addon.core.render.lod import build_lod
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.synthetic import random_scene


def _scene(n=6000, grow=1.0):
    s = random_scene(n, seed=21, sh_degree=1, extent=2.0)
    s.scales = (s.scales * grow).astype(np.float32)
    return s.subset(np.random.default_rng(2).permutation(s.count))


def _fresh(scene, batch, **kw):
    with SplatRenderer(scene, lod=kw.pop("lod", False)) as r:
        return np.stack(r.render(batch, **kw).images)


def test_small_face_after_a_large_one_sorts_its_own_instances():
    scene = _scene()
    big, small = ViewBatch.cubemap([0.1, 0.0, 0.2], 128), ViewBatch.cubemap([0.1, 0.0, 0.2], 16)
    with SplatRenderer(scene) as r:
        r.render(big)
        capacity = r.capacity
        for _ in range(2):  # the first frame learns the budget, the second is recorded for it
            got = np.stack(r.render(small).images)
        shape = r._shape(small)
        pairs, _ = r._caps(shape)
        assert pairs <= capacity // 2 and pairs >= 2 * r.render(small).instances
        assert np.array_equal(got, _fresh(scene, small))


@pytest.mark.parametrize("grow", [3.0, 5.0])  # within the instance buffers, past them
def test_a_frame_past_its_budget_is_drawn_again(grow):
    """The budget learnt far from the splats is outgrown in their midst: that frame is drawn again, sized anew."""
    scene = _scene(3000, grow)
    far, near = ViewBatch.cubemap([60.0, 0.0, 0.0], 64), ViewBatch.cubemap([0.0, 0.0, 0.0], 64)
    with SplatRenderer(scene) as r:
        r.render(far)
        r.render(far)
        shape = r._shape(far)
        before = r._caps(shape)[0]
        assert before < r.capacity
        res = r.render(near, wait=False)
        assert r.resolve(res)  # drawn again
        assert res.instances > before and r._caps(shape)[0] >= min(2 * res.instances, r.capacity)
        assert np.array_equal(np.stack(res.images), _fresh(scene, near))


def test_level_of_detail_cut_budget():
    """The cut's sort is sized for the cut a shape drew; a probe whose cut outgrows it is drawn again."""
    scene = _scene()
    tree = build_lod(scene)
    far, near = [25.0, 3.0, 0.0], [0.0, 0.0, 0.0]
    with SplatRenderer(scene, lod=tree) as r:
        r.render(ViewBatch.cubemap(far, 32), lod_k=4.0)
        r.render(ViewBatch.cubemap(far, 32), lod_k=4.0)
        shape = r._shape(ViewBatch.cubemap(far, 32), 4.0)
        cut_far = r._caps(shape)[1]
        assert cut_far <= r.cut_capacity // 2
        res = r.render(ViewBatch.cubemap(near, 32), lod_k=4.0, wait=False)
        assert r.resolve(res) and r.drawn > cut_far - 4096
        assert np.array_equal(np.stack(res.images), _fresh(scene, ViewBatch.cubemap(near, 32), lod=tree, lod_k=4.0))


def test_a_trimmed_renderer_draws_each_batch_once():
    """After trim() (a renderer kept between bakes gives back what a batch grew) a batch shape it drew before, and a
    new batch of probes like those it drew, get room in the instance list before they are recorded: drawn once
    (resolve draws nothing again), the same images as a fresh renderer's. Before, the first batch of every bake was
    drawn twice."""
    scene = _scene(3000, 3.0)
    origins = np.random.default_rng(5).uniform(-0.5, 0.5, (12, 3))
    four, twelve = ViewBatch.cubemaps(origins[:4], 64), ViewBatch.cubemaps(origins, 64)
    with SplatRenderer(scene) as r:
        first = r.render(four, wait=False)
        assert r.resolve(first)  # a new renderer's list is sized for a probe or two: drawn again
        r.trim()
        for batch in (four, twelve):  # the shape drawn before; a new shape, from what its probes drew
            res = r.render(batch, wait=False)
            assert not r.resolve(res) and res.instances > 4 * r._per_probe[r._probe_shape(four)] * 0.5
            assert np.array_equal(np.stack(res.images), _fresh(scene, batch))
