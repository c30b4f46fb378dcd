"""A cube whose six faces were rendered at different sizes (face size 0's per-face search, core/bake.py
choose_face_sizes), kept and put together on the GPU: no face is read back, resized on the host and uploaded again.

``GpuFaces`` keeps the faces at their own sizes in one buffer; ``put`` takes the faces a render just drew (its
GpuFrame, still in flight) and records, in one program queued behind the render: the new faces copied in beside
the kept ones, the cube at one size for the filters (``cube``: a frame-like AssembledCube that filter_probe, the
GPU hole fill and the GGX prefilter take as they take a renderer's frame) and the small cube the search splits into
faces' parts (``level``, read back from a host-visible copy). The filter queued after it makes one submission.

``HostFaces`` is the same on the host, the plain numpy reference (``faces_cube``: box.faces_to_size per face);
tests/test_gpu_assemble.py compares the two.
"""
from __future__ import annotations

import numpy as np

from ..vk import Buffer, Recorder, groups, scratch
from ..vk.kernels import KERNELS
from .box import faces_to_size
from .gpu_filters import omega_table

TEXEL = 16  # bytes of one RGBA float32 texel


def faces_cube(images, size: int) -> np.ndarray:
    """(6, size, size, C) float32 of six (n_f, n_f, C) faces of any power-of-two sizes: each face by itself to
    ``size`` (box.faces_to_size: the solid-angle mean of the texels a target texel covers, or bilinear doubling)."""
    return np.stack([faces_to_size(np.asarray(img)[None], size)[0] for img in images]).astype(np.float32)


class HostFaces:
    """The six faces on the host (read back), resized and stacked in numpy: the reference of GpuFaces."""

    def __init__(self, cube: np.ndarray) -> None:
        self.images = list(cube)
        self.sizes = [int(img.shape[0]) for img in self.images]

    def put(self, rendered, todo: dict[int, int], out: int, level: int) -> None:
        """As GpuFaces.put, from the render's images read back."""
        for f, image in zip(sorted(todo), rendered.images):
            self.images[f], self.sizes[f] = image, int(image.shape[0])
        self.cube = faces_cube(self.images, out)
        self._level = level

    def level(self) -> np.ndarray:
        """(6, level, level, 3) float64: the faces' RGB at put's ``level``."""
        return np.stack([faces_to_size(np.asarray(img[..., :3], np.float64)[None], self._level)[0]
                         for img in self.images])

    def close(self) -> None:
        pass


class AssembledCube:
    """A one-probe RGBA cube (6, n, n, 4) on the GPU, made by GpuFaces.put: read like a renderer's GpuFrame by the
    filters (gpu_filters: ``image``, ``face_size``, ``wait``), the hole fill (gpu_holes) and read_cube. Valid until
    its GpuFaces closes."""

    batch = None  # frame-like (gpu_filters._is_frame): made from views, not one batch of them
    probes = 1

    def __init__(self, owner: "GpuFaces", image: Buffer, size: int) -> None:
        self.owner, self.image, self.face_size = owner, image, size

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
            raise RuntimeError("this assembled cube was closed with its faces (GpuFaces.close)")

    def wait(self) -> bool:
        """Finish the render the faces came from and the assembly; True when either had to run again, so work
        queued on the cube meanwhile must run again (as GpuFrame.wait)."""
        self.check()
        return self.owner.finish()

    def read_cube(self) -> np.ndarray:
        self.wait()
        n = self.face_size
        return self.image.read(np.float32, self.pixels * 4).reshape(6, n, n, 4)


class GpuFaces:
    """The six faces at their own sizes on the GPU, from a one-probe cubemap frame of the renderer (copied at once,
    queued: the renderer's next render reuses the frame's buffer)."""

    def __init__(self, frame) -> None:
        frame.wait()
        self.ctx, n = frame.ctx, frame.face_size
        self.sizes = [n] * 6
        self._buffers: list[Buffer] = []
        self.store = self._buffer(6 * n * n * TEXEL, "probe-faces")
        self.cube: AssembledCube | None = None
        self._render, self._results, self._level = None, None, 0
        self._programs: list = []  # queued, not waited for: closed (waited) at close()
        rec = Recorder(self.ctx)
        rec.copy(frame.image, self.store, 6 * n * n * TEXEL)
        self._start(rec.program())

    def _buffer(self, nbytes: int, name: str) -> Buffer:
        b = scratch(self.ctx, nbytes, name)
        self._buffers.append(b)
        return b

    def _start(self, program) -> None:
        self._programs.append(program)
        program.start()

    def _offsets(self, sizes: list[int]) -> list[int]:
        return [sum(n * n for n in sizes[:f]) for f in range(6)]

    def put(self, rendered, todo: dict[int, int], out: int, level: int) -> None:
        """Keep the faces ``todo`` ({face: size}) that ``rendered`` (the RenderResult of those faces' views, in
        face order; it may still be in flight) drew, and record the cube at ``out`` (``self.cube``) and at
        ``level`` (``level()``), queued behind the render."""
        frame = rendered.frame
        old, old_at = self.store, self._offsets(self.sizes)
        sizes = list(self.sizes)
        for f in sorted(todo):
            sizes[f] = int(todo[f])
        at = self._offsets(sizes)
        store = self._buffer(sum(n * n for n in sizes) * TEXEL, "probe-faces")
        image = self._buffer(6 * out * out * TEXEL, "probe-assembled")
        small = self._buffer(6 * level * level * TEXEL, "probe-assembled-level")
        if self._results is None or self._results.nbytes < small.nbytes:
            if self._results is not None:
                self._results.destroy()
            self._results = Buffer.staging(self.ctx, small.nbytes, cached=True)
        rec = Recorder(self.ctx, reusable=True)
        drawn = 0
        for f in range(6):  # the new faces from the frame (its views in face order), the others kept
            n = sizes[f]
            if f in todo:
                rec.copy(frame.image, store, n * n * TEXEL, drawn * TEXEL, at[f] * TEXEL)
                drawn += n * n
            else:
                rec.copy(old, store, n * n * TEXEL, old_at[f] * TEXEL, at[f] * TEXEL)
        for dst, m in ((image, out), (small, level)):
            for f in range(6):
                n = sizes[f]
                if n == m:
                    rec.copy(store, dst, n * n * TEXEL, at[f] * TEXEL, f * m * m * TEXEL)
                else:
                    rec.dispatch(KERNELS["probe_faces_to_size"], [store, omega_table(self.ctx, n), dst],
                                 groups(m * m, 64, self.ctx), n=n, m=m, src_at=at[f], dst_at=f * m * m)
        rec.copy(small, self._results, 6 * level * level * TEXEL)
        self._start(rec.program())
        # the old store goes back to the pool at close(), once nothing queued reads it
        self.store, self.sizes, self._render, self._level = store, sizes, frame, level
        self.cube = AssembledCube(self, image, out)

    def finish(self) -> bool:
        """Wait for the render and the assembly queued behind it; run the assembly again (True) when the render
        had to be drawn again (GpuFrame.wait)."""
        redrawn = self._render.wait() if self._render is not None else False
        self._render = None  # settled: the renderer may render again without this cube going stale
        for program in self._programs:
            if program.running:
                program.wait()
        if redrawn:
            self._programs[-1].run()
        return redrawn

    def level(self) -> np.ndarray:
        """(6, level, level, 3) float64: the faces' RGB at put's ``level`` (the search's parts)."""
        self.finish()
        m = self._level
        return self._results.read(np.float32, 6 * m * m * 4).reshape(6, m, m, 4)[..., :3].astype(np.float64)

    def close(self) -> None:
        for program in self._programs:
            program.close()  # waits for it if it still runs
        self._programs = []
        for b in self._buffers:
            b.close()
        self._buffers = []
        if self._results is not None:
            self._results.destroy()
            self._results = None
