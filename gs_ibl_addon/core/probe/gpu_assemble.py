"""A cube whose six faces were rendered at different sizes (face size 0's per-face search, core/bake.py
choose_face_sizes), kept and put together on the GPU: no face is read back, resized on the host and uploaded again.

The search's two uniform cubes (32^2, 64^2) are kept on the GPU as they are rendered (``KeptCube``: a copy queued
between the render and its filter, no readback: a search that meets the tolerance with them never reads them).
``GpuFaces`` keeps the faces at their own sizes in one buffer, starting from the last of them, and gives both
cubes' small levels for the first parts in one readback. ``put`` takes the faces a render just drew (its GpuFrame,
still in flight) and records, in one program queued behind the render: the new faces copied in beside the kept
ones, the cube at one size for the filters (``cube``: a frame-like AssembledCube that filter_probe, the GPU hole
fill and the GGX prefilter take as they take a renderer's frame) and the small cube the search splits into faces'
parts (``level``, read back from a host-visible copy). The filter queued after it makes one submission.

``HostFaces`` is the same on the host, the plain numpy reference (``faces_cube``: box.faces_to_size per face);
tests/test_gpu_assemble.py compares the two.
"""
from __future__ import annotations

import numpy as np

from ..vk import Buffer, Recorder, groups, kept
from ..vk.kernels import KERNELS
from .box import faces_to_size
from .gpu_filters import omega_table

TEXEL = 16  # bytes of one RGBA float32 texel
PROGRAMS_KEPT = 16  # GpuFaces' recordings kept per context (a bake's search makes 2-5)
HELD_MAX = 8 << 20  # bytes: a store of faces larger than this is not kept between bakes


def faces_cube(images, size: int) -> np.ndarray:
    """(6, size, size, C) float32 of six (n_f, n_f, C) faces of any power-of-two sizes: each face by itself to
    ``size`` (box.faces_to_size: the solid-angle mean of the texels a target texel covers, or bilinear doubling)."""
    return np.stack([faces_to_size(np.asarray(img)[None], size)[0] for img in images]).astype(np.float32)


class HostFaces:
    """The six faces on the host (read back), resized and stacked in numpy: the reference of GpuFaces.
    ``host_parts(change, size)``: the bake's irradiance_parts."""

    def __init__(self, first: np.ndarray, last: np.ndarray, level: int, parts_size: int, host_parts) -> None:
        self.images = list(last)
        self.sizes = [int(img.shape[0]) for img in self.images]
        self._level, self._size, self._host_parts = level, parts_size, host_parts
        self._low = _levelled(first, level)

    def put(self, rendered, todo: dict[int, int], out: int) -> None:
        """As GpuFaces.put, from the render's images read back."""
        for f, image in zip(sorted(todo), rendered.images):
            self.images[f], self.sizes[f] = image, int(image.shape[0])
        self.cube = faces_cube(self.images, out)

    def parts(self) -> np.ndarray:
        """As GpuFaces.parts."""
        low = _levelled(self.images, self._level)
        change, self._low = low - self._low, low
        return self._host_parts(change, self._size)

    def close(self) -> None:
        pass


def _levelled(images, level: int) -> np.ndarray:
    return np.stack([faces_to_size(np.asarray(img[..., :3], np.float64)[None], level)[0] for img in images])


class CubeOnGpu:
    """A one-probe RGBA cube (6, n, n, 4) on the GPU, read like a renderer's GpuFrame by the filters (gpu_filters:
    ``image``, ``face_size``, ``wait``), the hole fill (gpu_holes) and ``read_cube``."""

    batch = None  # frame-like (gpu_filters._is_frame), though not one render's batch of views
    probes = 1

    def __init__(self, image: Buffer, size: int) -> None:
        self.image, self.face_size = image, size

    @property
    def ctx(self):
        return self.image.ctx

    @property
    def cube_face_size(self) -> int:
        return self.face_size

    @property
    def pixels(self) -> int:
        return 6 * self.face_size * self.face_size

    def check(self) -> None:
        if not self.image.alive:
            raise RuntimeError("this cube's buffer was given back (its bake is done with it)")

    def wait(self) -> bool:
        """Finish the work that makes the cube; True when it had to run again, so work queued on the cube meanwhile
        must run again (as GpuFrame.wait)."""
        raise NotImplementedError

    def read_cube(self) -> np.ndarray:
        self.wait()
        n = self.face_size
        return self.image.read(np.float32, self.pixels * 4).reshape(6, n, n, 4)


class KeptCube(CubeOnGpu):
    """A render's cube copied on the GPU, queued behind the render (still in flight): filter this instead of the
    frame and the copy goes to the GPU with the filter, in one submission, and outlives the renderer's next render
    (which reuses, or grows, the frame's buffer). ``slot``: which of a search's kept cubes (each its own buffer)."""

    def __init__(self, frame, slot: int = 0) -> None:
        frame.check()
        n = frame.face_size
        super().__init__(kept(frame.ctx, ("probe-kept", slot), 6 * n * n * TEXEL), n)
        self.size, self._frame = n, frame
        ctx, key = frame.ctx, ("kept-copy", frame.image.serial, self.image.serial, n)
        self.program = ctx.cache.get(key)
        if self.program is None or not self.program.valid:  # recorded once per frame buffer, kept buffer and size
            for old in [k for k, v in ctx.cache.items() if k[0] == "kept-copy" and not v.valid]:
                ctx.cache.pop(old).close()
            rec = Recorder(ctx, reusable=True)
            rec.copy(frame.image, self.image, 6 * n * n * TEXEL)
            self.program = ctx.cache[key] = rec.program()
        self.program.start()

    @property
    def buffer(self) -> Buffer:
        return self.image

    def wait(self) -> bool:
        self.check()
        redrawn = self._frame.wait() if self._frame is not None else False
        self._frame = None  # settled: the renderer may render again
        if self.program.running:
            self.program.wait()
        if redrawn:
            self.program.run()
        return redrawn

    def close(self) -> None:
        if self.program.running:  # the program and the buffer stay the context's
            self.program.wait()


class AssembledCube(CubeOnGpu):
    """GpuFaces.put's cube: valid until its GpuFaces closes."""

    def __init__(self, owner: "GpuFaces", image: Buffer, size: int) -> None:
        super().__init__(image, size)
        self.owner = owner

    def wait(self) -> bool:
        """Finish the render the faces came from and the assembly (GpuFaces.finish)."""
        self.check()
        return self.owner.finish()


class GpuFaces:
    """The six faces at their own sizes on the GPU, from the search's last cube (``last``, a KeptCube: the store
    starts as its buffer) and its first (``first``); both stay their owner's to close.

    ``parts()`` gives what the faces changed since the last call (first: since ``first``) split into each face's
    part of the irradiance at ``parts_size`` (bake.irradiance_parts of the change of the faces' RGB at ``level``):
    the levels, their change as six one-face cubes (probe_face_parts.comp) and the exact filter of those are queued
    with the faces' own work, so they go to the GPU in its submission. ``host_parts(change, size)``: take them on
    the host instead, from the levels read back (a CPU device, where numpy's integral is the faster).

    Its buffers are the context's (_held) and its recordings kept there by the buffers and sizes they use: the next
    bake of the same faces records nothing."""

    def __init__(self, first: KeptCube, last: KeptCube, level: int, parts_size: int, host_parts=None) -> None:
        self.ctx, n = last.ctx, last.size
        self.sizes = [n] * 6
        self.store = last.buffer
        self._rounds = 0
        self._programs: list = []  # started, maybe not yet waited for
        self.cube: AssembledCube | None = None
        self._render, self._level, self._size, self._host_parts = None, level, parts_size, host_parts
        level_bytes = 6 * level * level * TEXEL
        # the levels now and before (the change between them is what parts() splits): swapped at each put
        self._low = [kept(self.ctx, ("probe-faces-level", k), level_bytes) for k in range(2)]
        if host_parts is None:
            self._change = kept(self.ctx, ("probe-face-parts", level), 6 * level_bytes)
            self._plan = None
        else:
            self._results = kept(self.ctx, "probe-faces-level-read", 2 * level_bytes, staging=True)

        def record(rec: Recorder) -> None:
            self._record_resize(rec, first.buffer, [first.size] * 6, self._low[1], level)
            self._record_resize(rec, self.store, self.sizes, self._low[0], level)
            self._record_change(rec)
        self._start(("faces-init", first.buffer.serial, first.size, self.store.serial, n, level), record)

    def _start(self, key: tuple, record) -> None:
        """Start the recording of ``record`` kept under ``key`` (with every buffer its commands bind), recorded
        now if it is not; then the parts' filter behind it."""
        key = key + tuple(b.serial for b in self._low) + (
            self._change.serial if self._host_parts is None else self._results.serial,)
        program = self.ctx.cache.pop(key, None)
        if program is None or not program.valid:
            if program is not None:
                program.close()
            rec = Recorder(self.ctx, reusable=True)
            record(rec)
            program = rec.program()
            kept = [k for k in self.ctx.cache if isinstance(k, tuple) and k[0] in ("faces-init", "faces-put")]
            for old in kept[:max(0, len(kept) - PROGRAMS_KEPT + 1)]:  # the least recently used
                self.ctx.cache.pop(old).close()
        self.ctx.cache[key] = program
        self._programs.append(program)
        program.start()
        if self._host_parts is None:  # the parts' filter, queued behind: one plan, recorded once (its source kept)
            from .gpu_filters import plan_for
            self._plan = plan_for(self.ctx, self._change, True, self._level, "exact", self._size, 6,
                                  phi_steps=64, theta_steps=16, box_level_size=1, downsample_to=self._level)
            self._plan.program.start()

    @staticmethod
    def _offsets(sizes: list[int]) -> list[int]:
        return [sum(n * n for n in sizes[:f]) for f in range(6)]

    def _record_resize(self, rec: Recorder, src: Buffer, sizes: list[int], dst: Buffer, m: int) -> None:
        """Record the faces of ``src`` (``sizes``, one after another) to one cube of m^2 faces in ``dst``."""
        at = self._offsets(sizes)
        for f, n in enumerate(sizes):
            if n == m:
                rec.copy(src, dst, n * n * TEXEL, at[f] * TEXEL, f * m * m * TEXEL)
            else:
                rec.dispatch(KERNELS["probe_faces_to_size"], [src, omega_table(self.ctx, n), dst],
                             groups(m * m, 64, self.ctx), n=n, m=m, src_at=at[f], dst_at=f * m * m)

    def _record_change(self, rec: Recorder) -> None:
        """Record what parts() takes of the levels now (_low[0]) and before (_low[1])."""
        m = self._level
        if self._host_parts is None:
            rec.dispatch(KERNELS["probe_face_parts"], [self._low[0], self._low[1], self._change],
                         groups(36 * m * m, 64, self.ctx), n=m)
        else:
            for k in range(2):
                rec.copy(self._low[k], self._results, 6 * m * m * TEXEL, 0, k * 6 * m * m * TEXEL)

    def put(self, rendered, todo: dict[int, int], out: int) -> None:
        """Keep the faces ``todo`` ({face: size}) that ``rendered`` (the RenderResult of those faces' views, in
        face order; it may still be in flight) drew, and record the cube at ``out`` (``self.cube``) and what
        parts() takes, queued behind the render."""
        frame = rendered.frame
        old, old_sizes = self.store, list(self.sizes)
        sizes = list(self.sizes)
        for f in todo:
            sizes[f] = int(todo[f])
        old_at, at = self._offsets(old_sizes), self._offsets(sizes)
        # the stores of successive rounds alternate (a round copies the last one's kept faces)
        store = kept(self.ctx, ("probe-faces", self._rounds % 2), sum(n * n for n in sizes) * TEXEL)
        image = kept(self.ctx, ("probe-assembled", out), 6 * out * out * TEXEL)  # a round's cube replaces the last
        self._low.reverse()  # the level now becomes the one before

        def record(rec: Recorder) -> None:
            drawn = 0
            for f in range(6):  # the new faces from the frame (its views in face order), the others kept
                n = sizes[f]
                if f in todo:
                    rec.copy(frame.image, store, n * n * TEXEL, drawn * TEXEL, at[f] * TEXEL)
                    drawn += n * n
                else:
                    rec.copy(old, store, n * n * TEXEL, old_at[f] * TEXEL, at[f] * TEXEL)
            self._record_resize(rec, store, sizes, image, out)
            self._record_resize(rec, store, sizes, self._low[0], self._level)
            self._record_change(rec)
        self._start(("faces-put", frame.image.serial, old.serial, store.serial, image.serial, tuple(old_sizes),
                     tuple(sizes), out, self._level), record)
        self.store, self.sizes, self._render = store, sizes, frame
        self._rounds += 1
        self.cube = AssembledCube(self, image, out)

    def finish(self) -> bool:
        """Wait for the render and the work queued behind it; run the assembly (and the parts' filter) again
        (True) when the render had to be drawn again (GpuFrame.wait)."""
        redrawn = self._render.wait() if self._render is not None else False
        self._render = None  # settled: the renderer may render again without this cube going stale
        for program in self._programs:
            if program.running:
                program.wait()
        if redrawn:
            self._programs[-1].run()
            if self._host_parts is None:
                self._plan.program.wait()
                self._plan.program.start()
        return redrawn

    def parts(self) -> np.ndarray:
        """(6, 6, size, size, 3) float64: the change of the faces since the last call, per face's part of the
        irradiance (bake.irradiance_parts)."""
        self.finish()
        if self._host_parts is None:
            return self._plan.finish_all()[1].astype(np.float64)
        m = self._level
        low = self._results.read(np.float32, 2 * 6 * m * m * 4).reshape(2, 6, m, m, 4)[..., :3].astype(np.float64)
        return self._host_parts(low[0] - low[1], self._size)

    def close(self) -> None:
        """Wait for what it started; its buffers and recordings stay the context's, but for stores over
        HELD_MAX (a face of 1024^2, or two of 512^2), which are given back."""
        for program in self._programs:
            if program.running:
                program.wait()
        self._programs = []
        if self._host_parts is None and self._plan is not None and self._plan.program.running:
            self._plan.program.wait()
        for k in range(2):
            b = self.ctx.cache.get(("probe-faces", k))
            if b is not None and b.nbytes > HELD_MAX:
                self.ctx.cache.pop(("probe-faces", k)).destroy()
