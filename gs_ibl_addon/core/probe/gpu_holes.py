"""Holes of a batch of rendered probes filled on the GPU, by probe/holes.py's rule for a fill that is one colour over
the sphere ("mean", "constant"): a batch that keeps only its SH and irradiance (a grid's nodes, Lighting Auto's
measurement) then reads no cube back and uploads none again (core/bake_batch.py), where the host fill of 18 probes
of 64^2 faces and their round trip cost ~130 ms of host time on lavapipe's machine.

The mean fill needs no cube on the host either: the filter's SH DC term is sum(rgb dOmega) Y00 and its hole
fraction h says sum(clamp(alpha) dOmega) = 4 pi (1 - h), so covered_mean = DC / (Y00 4 pi (1 - h)).
"""
from __future__ import annotations

import contextlib
import math
from typing import Iterator

import numpy as np

from ..vk import Buffer, Recorder, groups, kept, scratch
from ..vk.kernels import KERNELS

Y00 = 0.5 / math.sqrt(math.pi)
GPU_FILLS = ("mean", "constant")  # holes.py's fills of one colour over the sphere: the ones filled here
# fill_frame_holes(read=True) copies a frame of at most this many bytes (a 64^2 cube: 0.4 MB, 128^2: 1.6 MB) into a
# host-visible buffer the context keeps; a larger one is read as before, by its own staging copy
READ_WITH_FILL_MAX = 16 << 20


def covered_means(sh: np.ndarray, holes: np.ndarray) -> np.ndarray:
    """(N, 3) holes.covered_mean of each probe, from its (N, >=1, 3) radiance SH and (N,) hole fraction as the
    filters give them (zeros where nothing is covered)."""
    covered = 4.0 * np.pi * (1.0 - np.asarray(holes, np.float64))
    dc = np.asarray(sh, np.float64)[:, 0, :3] / Y00
    return np.where(covered[:, None] > 0, dc / np.maximum(covered, 1e-300)[:, None], 0.0)


class FilledFrame:
    """What ``fill_frame_holes(..., read=True)`` yields: ``read()`` gives the filled frame's RGBA, (P, 6, n, n, 4)
    float32, once the work queued in the block is waited for. Where the frame's memory is not host-cached (a
    discrete GPU, which reads it through a staging copy: one more submission) the fill's own program copies it to a
    host-visible buffer the context keeps (frames up to READ_WITH_FILL_MAX), so the read is a memcpy; valid until
    the next fill that reads."""

    def __init__(self, frame, staged: Buffer | None) -> None:
        self.frame, self.staged = frame, staged

    def read(self) -> np.ndarray:
        frame, n = self.frame, self.frame.cube_face_size
        source = self.staged if self.staged is not None else frame.image
        return source.read(np.float32, frame.pixels * 4).reshape(frame.probes, 6, n, n, 4)


@contextlib.contextmanager
def fill_frame_holes(frame, fills: np.ndarray, read: bool = False) -> Iterator[FilledFrame | None]:
    """``with fill_frame_holes(frame, fills): filter(frame)``: add (1 - alpha) x fills[probe] to the RGB of every
    texel of a render_probes frame on the GPU (in place; alpha is kept, as holes.fill_holes keeps it). The fill is
    queued, not waited for: the work started inside the block goes to the GPU with it, in one submission.
    ``read``: yield a FilledFrame whose read() gives the filled cubes without a submission of its own."""
    frame.wait()
    ctx, probes = frame.ctx, frame.probes
    fill = np.zeros((probes, 4), np.float32)
    fill[:, :3] = np.asarray(fills, np.float64).reshape(probes, 3)
    total = frame.pixels
    image = frame.image
    staged = (kept(ctx, "hole-fill-read", total * 16, staging=True)
              if read and not (image.host_visible and image.host_cached)
              and total * 16 <= READ_WITH_FILL_MAX else None)
    buf = scratch(ctx, fill.nbytes, "hole-fill")
    prog = None
    try:
        buf.write(fill)
        rec = Recorder(ctx)
        rec.dispatch(KERNELS["probe_fill_holes"], [image, buf], groups(total, 256, ctx), n=total,
                     per_probe=total // probes)
        if staged is not None:
            rec.copy(image, staged, total * 16)
        prog = rec.program()
        prog.start()
        yield FilledFrame(frame, staged) if read else None
    finally:
        if prog is not None:
            prog.close()  # waits for it if the block did not
        buf.close()
