"""The GPU splat renderer: scene buffers uploaded once, then any batch of views rendered in one submission.

``render(batch)`` returns a RenderResult whose ``frame`` (GpuFrame) stays on the GPU: the probe filters take it
as it is, and only what is looked at (``images``, ``depths``) is read back. Depth is written only when asked.
Each batch shape is recorded once into a Program and submitted again for every later render of that shape (the
probe position travels in a buffer), so a render costs the host one submit and one wait.

Stages (each a compute dispatch, timed with timestamp queries when asked):
  preprocess   per splat, once for all views: cull, ray-evaluation frame, SH colour, tiles touched, depth key
  sort_depth   radix sort of splats by distance from the origin (one order serves all six cube faces), or for a
               batch of one view by depth along its axis (3DGS's order; splat_math.sort_depths); splats are
               uploaded in tie order (render/upload.py), which its stable passes keep among equal keys
  emit         prefix sum of tile counts in depth order, then one (tile, splat) instance per touched tile
  sort_tiles   stable radix sort of instances by tile id (depth order survives inside each tile)
  ranges       each tile's run of instances
  raster       one workgroup per tile of every view, front-to-back compositing with early termination
The instance list is sized from the previous frame; if a frame needs more, it is re-rendered once with room.

With a level of detail (``SplatRenderer(scene, lod=True)``, render/lod.py) the GPU holds every node of the tree
and ``render(batch, lod_k=k)`` draws the cut of threshold k x pixel angle: preprocess decides per node and flags
the drawn ones, a prefix sum and gs_lod_compact pack them in tie order, and the later stages see only those.

Many probes in one submission (``render_probes(origins, face_size)``, a ViewBatch.cubemaps). Every stage above
works on (probe, splat) pairs instead of splats: gs_preprocess runs once per pair (workgroup x = the probe) and
writes its outputs at pair index probe * n + splat, with the probe's own distance, colour, cut and first tile id.
One depth sort of all pairs by their depth key then leaves each probe's pairs in exactly the order its own render
would give them (a stable sort; equal keys keep pair order, and within a probe that is tie order), the tile ids
of emit span the 6N faces, and the stable tile sort, ranges and raster (workgroup z = the probe) need nothing
more. So each probe of a batch is the single-probe render of its position, up to the raster's chunking (a 32^2
probe alone is split into chunks, a batch of them is not): float rounding, <= 2e-4 (tests/test_multi_probe.py).
Memory grows with probes x splats (PAIR_BYTES a pair); ``probes_per_group`` sizes a group of probes to the
device (largest storage binding, a share of the device heap) and a batch of more probes is recorded as several
groups one after another in the same submission, reusing the pair buffers.
"""
from __future__ import annotations

import sys
import time
import warnings
import weakref
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..colour import check_colour_space
from ..scene import SplatScene
from ..vk import Buffer, Program, Recorder, get_context, groups
from ..vk.constants import DEPTH_KEY_BITS, MAX_VIEWS, PREP, TILE, VIEW_BYTES, VIEW_ROWS
from ..vk.kernels import KERNELS
from . import kernel_table
from .gpu_sort import RadixSorter, Scanner
from .lod import LodTree, build_lod
from .splat_math import DEFAULT_NEAR
from .upload import gpu_splats
from .views import ViewBatch

# A 32^2 cubemap has only 24 tiles, too few workgroups for a GPU: below CHUNK_BELOW_TILES tiles per probe each
# tile's list is split into chunks composited in parallel (gs_raster.comp / gs_merge.comp), up to
# RASTER_TARGET_GROUPS workgroups for the whole group of probes. Chunks give up the early termination of pixels that
# turned opaque in an earlier chunk, so they only pay while workgroups are few: on an H200, for 1M splats, 32 chunks
# took a 32^2 probe's raster from 2.0 to 1.1 ms, while 10 chunks made 64^2 slower than one pass (1.16 vs 0.76 ms)
# (docs/bench/runs/chunk_experiment.md). In a batch of 32^2 probes, chunking every probe as if alone (32 chunks)
# measured 9.0 ms raster at 8 probes (11.6 unchunked) but 27.1 at 27 (13.3 unchunked) and 122 at 125 (44.1)
# (docs/bench/multi_probe_nvidia-h200*.csv): the target counts the group's tiles, not one probe's. The partial
# images of the chunks are bounded by CHUNK_BYTES (one storage binding, and memory a large batch would multiply).
RASTER_TARGET_GROUPS = 1024
# A CPU device (lavapipe) is full with a few workgroups per core, and there chunks only cost the early termination:
# the guitar capture's 32^2 probe rastered in 6.5 s with 1024 as the target (32 chunks), 0.9 s with 16 (one), where
# its 64^2 probe takes 1.3 s (2 cores, 2026-12-03).
CPU_RASTER_TARGET_GROUPS = 16
MAX_RASTER_CHUNKS = 32
CHUNK_BELOW_TILES = 64
CHUNK_BYTES = 128 << 20
# llvmpipe (lavapipe) ends every loop of a shader invocation once they have run 65,535 iterations in all (Mesa's
# LP_MAX_TGSI_LOOP_ITERATIONS), silently: a raster workgroup past it composites no more pairs (a 1M-splat shell at
# 16² faces came out 0.987 covered for the reference's 0.995). So on a CPU device the pairs one workgroup takes stay
# within these, per raster kernel (its loop steps a pair: one, and one a batch of 256; the conic's up to two, its
# 32-step mask loop and the ray tests of those that pass); a frame whose deepest chunk is past them is drawn again in
# more chunks (resolve; tests/test_loop_limit.py).
# The strip kernels step once a pair of the pixel's strip, once per 32 pairs and once a batch: 60k pairs stay within.
LOOP_PAIRS = {"gs_raster": 60_000, "gs_raster_conic": 30_000, "gs_raster_strips": 60_000,
              "gs_raster_conic_strips": 60_000}
LOOP_PAIRS.update({k + "_cut": v for k, v in LOOP_PAIRS.items()})  # the depth cut's kernels loop as theirs


def target_groups(ctx) -> int:
    """The workgroups a raster should reach on this device before its tiles' lists are split into chunks."""
    return CPU_RASTER_TARGET_GROUPS if ctx.is_cpu else RASTER_TARGET_GROUPS


def chunks_that_fit(partial_bytes_per_chunk: int) -> int:
    """The most chunks whose partial images (``partial_bytes_per_chunk`` each) CHUNK_BYTES holds, at least one."""
    return max(1, CHUNK_BYTES // max(1, int(partial_bytes_per_chunk)))


def raster_chunks(tiles_per_probe: int, probes: int = 1, partial_bytes_per_chunk: int = 0,
                  target: int | None = None) -> int:
    """Chunks per tile list for a group of ``probes`` probes of ``tiles_per_probe`` tiles each;
    ``partial_bytes_per_chunk``: one chunk's partial image(s) for the whole group, which CHUNK_BYTES bounds;
    ``target``: the device's target_groups (default: a GPU's)."""
    if tiles_per_probe >= CHUNK_BELOW_TILES:
        return 1
    target = RASTER_TARGET_GROUPS if target is None else int(target)
    chunks = min(MAX_RASTER_CHUNKS, max(1, target // max(1, tiles_per_probe * max(1, probes))))
    if partial_bytes_per_chunk > 0:
        chunks = min(chunks, chunks_that_fit(partial_bytes_per_chunk))
    return int(max(1, chunks))


# Benchmarks only: a timestamp after each step of both sorts (labels "<stage>.hist", ".scan", ".scatter").
PROFILE_SORTS = False
# Faces from CONIC_MIN_FACE to CONIC_MAX_FACE raster with each pair's footprint conic tested before the ray test
# (gs_raster_conic: 32 pairs' conics, then the ray test of those that pass): their tiles hold many pairs for 256
# pixels, and the cheap test is what a pixel mostly does. Raster ms on an H200 (docs/benchmarks.md, 2026-12-03), ray
# test alone -> conic first: 6M splats at 64² random 3.52 -> 1.81, shell 12.67 -> 6.53; at 256² random 1.32 -> 1.31,
# shell 5.67 -> 4.33 (1M: 0.36 -> 0.48, 1.02 -> 0.90); at 1024² slower (6M 3.22 -> 5.49, 9.71 -> 10.40), where each
# tile holds a few batches of pairs and the conic's setup and registers cost more than the test saves; at 32² slower
# too (1M splats 0.66 -> 0.78, a 13k-node level-of-detail cut 0.031 -> 0.044). Lavapipe: within +-10% up to 256².
# 256² is in: the dense scenes gain most there (6M shell -1.3 ms), the sparse ones lose ~0.1 ms.
CONIC_MIN_FACE, CONIC_MAX_FACE = 64, 256


def raster_conic(batch: ViewBatch) -> bool:
    """Whether ``batch`` rasters with the conic pre-test (every view's larger side within the conic's range; a
    window of a frame, a render border, goes by its frame's, and so draws the frame's pixels)."""
    sides = [max(v.grid) for v in batch.views]
    return CONIC_MIN_FACE <= min(sides) and max(sides) <= CONIC_MAX_FACE


# Strip masks (gs_raster.glsl RASTER_STRIPS): the loader bounds each pair's footprint to the tile's strips of two
# pixel rows it may reach, and a pixel steps only over its strip's pairs. The images are the same bit for bit (the
# bound is padded far past rounding and drops only pairs every pixel of the strip would reject). Emit with one thread
# per splat (gs_emit.glsl EMIT_PER_SPLAT): each splat writes its own instance slots, with no search for the splat
# owning a slot and its footprint's quadric taken once, where one thread per slot keeps a warp's work even. Same
# slots, same keys. Which of each pair a device takes, per frame size, is measured, not set here: the kernel table
# (render/kernel_table.json, written by benchmarks/raster_ab_bench.py table from A/B timings; kernel_table.py has the
# rule and the fallback for a device class it has no rows for).
RASTER_STRIPS: bool | None = None  # None: the kernel table's choice; True / False: every device (tests, A/B rows)
EMIT_PER_SPLAT: bool | None = None  # likewise for the per-splat emit
# The per-splat emit's loop steps once per instance of a splat, so it is taken only while a probe's views hold at
# most EMIT_PER_SPLAT_MAX_TILES tiles (lavapipe's loop limit, LOOP_PAIRS above), whatever the table says.
EMIT_PER_SPLAT_MAX_TILES = 60_000


def batch_face(batch: ViewBatch) -> int:
    """The frame size the kernel table is looked up by: the larger side of the batch's largest view (of its frame,
    for a window of one)."""
    return max(max(v.grid) for v in batch.views)


_DEVICE_CLASS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()  # per context, asked of Vulkan once


def _device_class(ctx) -> str:
    cls = _DEVICE_CLASS.get(ctx)
    if cls is None:
        cls = _DEVICE_CLASS[ctx] = kernel_table.context_class(ctx)
    return cls


def kernel_picks(ctx, face: int) -> dict[str, kernel_table.Pick]:
    """Per stage ("raster", "emit"), the kernel_table choice for frames of larger side ``face`` on ``ctx``, with the
    module switches (RASTER_STRIPS, EMIT_PER_SPLAT) overriding it where they are set."""
    table, cls = kernel_table.load(), _device_class(ctx)
    picks = {stage: table.pick(cls, stage, face) for stage in kernel_table.CHOICES}
    if RASTER_STRIPS is not None:
        picks["raster"] = kernel_table.Pick("strips" if RASTER_STRIPS else "plain", "renderer.RASTER_STRIPS")
    if EMIT_PER_SPLAT is not None:
        picks["emit"] = kernel_table.Pick("splat" if EMIT_PER_SPLAT else "slot", "renderer.EMIT_PER_SPLAT")
    return picks


def raster_strips(ctx, face: int = 64) -> bool:
    """Whether rasters of frames of larger side ``face`` on ``ctx``'s device use the strip kernels."""
    return kernel_picks(ctx, face)["raster"].kernel == "strips"


def emit_per_splat(ctx, tiles_per_probe: int, face: int | None = None) -> bool:
    """Whether a batch of ``tiles_per_probe`` tiles a probe (frames of larger side ``face``; None: the cube faces
    holding that many tiles) emits its instances one thread per splat on ``ctx``."""
    if face is None:
        face = TILE * max(1, round((tiles_per_probe / 6) ** 0.5))
    return kernel_picks(ctx, face)["emit"].kernel == "splat" and tiles_per_probe <= EMIT_PER_SPLAT_MAX_TILES


def raster_kernel(batch: ViewBatch, strips: bool = False, cut: bool = False) -> str:
    """The raster kernel that draws ``batch`` (``strips``: raster_strips of the device; ``cut``: with a depth cut,
    FRONT and BEHIND layers, render(cut=...))."""
    name = "gs_raster_conic" if raster_conic(batch) else "gs_raster"
    return name + ("_strips" if strips else "") + ("_cut" if cut else "")


def batch_kernels(ctx, batch: ViewBatch, tiles_per_probe: int, cut: bool = False) -> dict[str, str]:
    """The kernels a render of ``batch`` dispatches for its raster and emit (core/vk/kernels.py names; "emit" is
    the last of the emit's kernels), and where the choice came from ("raster_source", "emit_source"); ``cut``: the
    render has a depth cut (the *_cut raster, chosen with the same strips as without)."""
    picks = kernel_picks(ctx, batch_face(batch))
    splat = picks["emit"].kernel == "splat" and tiles_per_probe <= EMIT_PER_SPLAT_MAX_TILES
    return {"raster": raster_kernel(batch, picks["raster"].kernel == "strips", cut),
            "emit": "gs_emit_per_splat" if splat else "gs_emit",
            "raster_source": picks["raster"].source,
            "emit_source": picks["emit"].source if splat == (picks["emit"].kernel == "splat") else
            f"{picks['emit'].source}, past EMIT_PER_SPLAT_MAX_TILES"}


# The plain raster kernel evaluates each pair whose centre is well in front of the view through its exact forms in
# the image plane (gs_raster.glsl plane_form, splat_math.plane_form): the ray test's m with less arithmetic per pixel
# and no cancellation for small far splats. False: the ray test for every pair (tests, benchmarks' A/B).
PLANE_FORMS = True
# The SH buffer's layout, chosen when a renderer uploads its scene (render/upload.py): False coefficient-major, the
# layout whose loads a warp shares when every lane draws (probes: every splat is in some face); True splat-major,
# one splat's coefficients together, for views that see a fraction of the splats (a camera's ~1/8).
SH_SPLAT_MAJOR: bool | None = None  # None: the device's (splat-major on a GPU, coefficient-major on a CPU device)
# A single view (a camera frame, one face alone) sees a fraction of the splats: its drawn pairs are packed before
# the depth sort (gs_preprocess's flags, a prefix sum, gs_lod_compact: the level of detail's way), so the sort and
# the stages after it run over those alone. False: every pair is sorted, the culled ones keyed last (A/B rows).
COMPACT_VIEWS = True

# A batch shape's recordings sort and emit for twice what it drew (two frames apart, a moving view rarely draws
# twice as much; a frame that does is drawn again), within the renderer's buffers; from its first frame, once that
# halves them (else the first recording is kept: recording again costs more than sorting empty blocks).
def budget_for(count: int) -> int:
    return 2 * int(count) + 4096


def budget_fit(count: int, cap: int) -> int:
    return budget_for(count) if budget_for(count) <= cap // 2 else cap


PROGRAMS_KEPT = 16  # recorded batch shapes per renderer (a face-size search uses three, Auto's batches two, a
# light volume's about five)

# GPU bytes per (probe, splat) pair: prepared (PREP vec4), tile rectangles (MAX_VIEWS uvec2), tile count, depth
# key and value, the counts' prefix sum, the depth sort's scratch key and value; with a level of detail also the
# compacted keys and values.
PAIR_BYTES = PREP * 16 + MAX_VIEWS * 8 + 4 * 4 + 8
PAIR_BYTES_LOD = PAIR_BYTES + 8
INSTANCE_BYTES = 16  # key, value and the tile sort's scratch copies
INSTANCES_PER_PAIR = 2  # planning figure for sizing (a 32^2 probe of bench_scene: ~1.5); overflow redraws
GROUP_HEAP_SHARE = 0.5  # of the device's largest heap, for the pair and instance buffers of one group


# A renderer kept between bakes (Blender's splat cache) keeps what its batches grew while that is within this share of
# the device's largest heap (trim(keep_within=...)): its next bake then makes no buffers and records no programs
# again. The sample room's light volume on an H100 (volume_bench, 2026-12-06, one run): 131-152 ms a bake with them
# given back before it (116-121 ms of host), 36-44 ms kept.
BAKE_KEEP_SHARE = 1 / 16


# A pair's first tile travels as a float in its prepared record (gs_preprocess -> gs_emit): exact below 2^24, so a
# group's tiles stay below it (a thousand 256^2 probes are 1.5M tiles).
MAX_GROUP_TILES = 1 << 24

# Frame bytes per cube pixel of a batch: the RGBA float image, and the filter's packed RGB copy (gpu_filters).
FRAME_BYTES_PER_PIXEL = 16 + 12


def _binding_limit(ctx) -> int:
    return ctx.max_storage_range


def largest_probe_face(ctx, n_probes: int) -> int:
    """The largest power-of-two face size whose frame of ``n_probes`` cubemaps fits one storage binding and
    GROUP_HEAP_SHARE of the device's largest heap (the frame is one buffer; the pair buffers split into groups,
    the frame does not)."""
    from ..limits import device_local_bytes
    room = min(_binding_limit(ctx) // 16, int(GROUP_HEAP_SHARE * device_local_bytes(ctx)) // FRAME_BYTES_PER_PIXEL)
    face = 1
    while 6 * n_probes * (2 * face) ** 2 <= room:
        face *= 2
    return face


def check_probes_fit(ctx, n_probes: int, face_size: int) -> None:
    """A ValueError naming what fits when the frame of ``n_probes`` cubemaps of ``face_size``^2 does not."""
    if n_probes > 1 and face_size > largest_probe_face(ctx, n_probes):
        mib = n_probes * 6 * face_size ** 2 * FRAME_BYTES_PER_PIXEL / 2 ** 20
        raise ValueError(f"{n_probes} probes of {face_size}^2 faces need a {mib:,.0f} MiB frame, more than "
                         f"{ctx.device_name} holds in one buffer: use faces of {largest_probe_face(ctx, n_probes)}^2 "
                         "or less, or fewer probes per batch")


# A camera frame's GPU bytes a pixel with a depth cut: FRONT and BEHIND (RGBA float), depth and the cut (a float each).
CAMERA_BYTES_PER_PIXEL = 16 + 16 + 4 + 4


def largest_camera_frame(ctx, width: int, height: int) -> tuple[int, int]:
    """The largest frame of ``width``:``height``'s shape (each side scaled by one factor, rounded down) whose images
    fit this device: a 16-byte-a-pixel image in one storage binding, and CAMERA_BYTES_PER_PIXEL a pixel in
    GROUP_HEAP_SHARE of its largest heap. (width, height) itself when it fits."""
    from ..limits import device_local_bytes
    room = min(_binding_limit(ctx) // 16, int(GROUP_HEAP_SHARE * device_local_bytes(ctx)) // CAMERA_BYTES_PER_PIXEL)
    w, h = int(width), int(height)
    if w * h <= room:
        return w, h
    f = (room / (w * h)) ** 0.5
    w2, h2 = max(1, int(w * f)), max(1, int(h * f))
    while w2 * h2 > room:
        w2, h2 = max(1, w2 - 1), max(1, round(h * (w2 - 1) / w))
    return w2, h2


def check_camera_fits(ctx, width: int, height: int) -> None:
    """Refuse a camera frame (the pixels it renders: a border's window, not the whole frame) whose images this
    device cannot hold, before anything is drawn: limits.TooBig (a ValueError) naming the size that fits."""
    w2, h2 = largest_camera_frame(ctx, width, height)
    if (w2, h2) == (int(width), int(height)):
        return
    from ..limits import TooBig, _mib, device_local_bytes
    px = int(width) * int(height)
    raise TooBig("resolution", int(width),
                 f"a {width}x{height} camera frame needs {_mib(px * CAMERA_BYTES_PER_PIXEL)} of GPU memory for its "
                 f"images ({_mib(16 * px)} each for FRONT and BEHIND) but {ctx.device_name} holds "
                 f"{_mib(_binding_limit(ctx))} in one buffer and {_mib(device_local_bytes(ctx))} in all: render "
                 f"{w2}x{h2} or smaller ({100 * w2 / int(width):.0f}% of this size), or the frame in parts with render "
                 "borders (ViewBatch.camera's window)")


def probes_per_group(ctx, nodes: int, n_probes: int, lod: bool = False) -> int:
    """How many probes of ``nodes`` splats (or level-of-detail nodes) one group renders at once: every per-pair
    buffer within the device's largest storage binding, pairs and instances within GROUP_HEAP_SHARE of its
    largest heap, and the probe count within the dispatch's z limit. At least 1 (a single probe is what the
    renderer always needed)."""
    from ..limits import device_local_bytes
    nodes = max(1, int(nodes))
    binding = _binding_limit(ctx)
    per_probe = nodes * ((PAIR_BYTES_LOD if lod else PAIR_BYTES) + INSTANCES_PER_PAIR * INSTANCE_BYTES)
    g = min(int(n_probes), int(ctx.max_workgroups[2]),
            binding // (nodes * PREP * 16),  # the largest per-pair buffer
            binding // (nodes * INSTANCES_PER_PAIR * 4),
            int(GROUP_HEAP_SHARE * device_local_bytes(ctx)) // per_probe)
    return max(1, g)


class StaleFrame(RuntimeError):
    """A GpuFrame read after its renderer rendered again (the frame's buffers now hold the newer image)."""


@dataclass(eq=False)
class GpuFrame:
    """One rendered batch on the GPU: ``image`` holds premultiplied linear RGB + coverage (float32 RGBA) per pixel,
    views one after another (a cubemap: faces +X, -X, +Y, -Y, +Z, -Z, rows top first); ``depth`` the view-space z
    per pixel (0: nothing seen) when the render was asked for it, else None. A render given a depth cut
    (render(cut=...)) holds its FRONT layer in ``image`` and its BEHIND layer in ``behind`` (else None), and its
    depth is that of FRONT over BEHIND.

    The buffers belong to the renderer and are reused by its next render: a frame is valid until then (reading a
    stale one raises StaleFrame). Filters take it without a host round trip (probe.gpu_filters).
    """
    renderer: "SplatRenderer"
    batch: ViewBatch
    image: Buffer
    depth: Buffer | None
    generation: int
    behind: Buffer | None = None

    @property
    def ctx(self):
        return self.renderer.ctx

    @property
    def pixels(self) -> int:
        return self.batch.n_probes * sum(v.width * v.height for v in self.batch.views)

    @property
    def probes(self) -> int:
        """Probes in the frame (render_probes); 1 for a single batch."""
        return self.batch.n_probes

    @property
    def face_size(self) -> int:
        """The face size of a one-probe cubemap frame (six square views). A frame of several probes refuses, so
        that a single-probe filter never reads only its first probe: see cube_face_size."""
        if self.probes != 1:
            raise ValueError(f"this frame holds {self.probes} probes: filter them with probe.gpu_filters."
                             "filter_probes, or read them with read_probes()")
        return self.cube_face_size

    @property
    def cube_face_size(self) -> int:
        """The face size of each cubemap of the frame (render_probes: every probe's)."""
        v = self.batch.views
        if len(v) != 6 or any(x.width != v[0].width or x.height != v[0].width for x in v):
            raise ValueError("this frame is not a cubemap (six square faces)")
        return v[0].width

    def check(self) -> None:
        if self.generation != self.renderer.generation or not self.image.alive:
            raise StaleFrame("this frame was overwritten by a later render of the same renderer; "
                             "read it (or filter it) before rendering again")

    def wait(self) -> bool:
        """Finish the render (``render(..., wait=False)`` returns before the GPU is done). True when it had to be
        drawn again (its instance list outgrew the renderer's capacity, or a CPU device's loops needed more chunks:
        LOOP_PAIRS): work queued on the frame meanwhile saw an incomplete image and must run again."""
        self.check()
        return self.renderer.resolve()

    def _split(self, flat: np.ndarray, channels: int) -> list[np.ndarray]:
        out, off = [], 0
        for v in self.batch.views * self.batch.n_probes:
            npx = v.width * v.height
            shape = (v.height, v.width, channels)[:2 + (channels > 1)]
            out.append(flat[off * channels:(off + npx) * channels].reshape(shape))
            off += npx
        return out

    def read_images(self) -> list[np.ndarray]:
        """Per view (H, W, 4) float32, read back from the GPU (every probe's views, probe after probe)."""
        self.wait()
        return self._split(self.image.read(np.float32, self.pixels * 4), 4)

    def read_cube(self) -> np.ndarray:
        """A cubemap frame as one (6, N, N, 4) float32 array, read back from the GPU (no per-face copies)."""
        if self.probes != 1:
            raise ValueError(f"this frame holds {self.probes} probes: read_probes() reads them all")
        return self.read_probes()[0]

    def read_probes(self) -> np.ndarray:
        """A frame of P cubemaps (render_probes) as one (P, 6, N, N, 4) float32 array read back from the GPU."""
        n = self.cube_face_size
        self.wait()
        return self.image.read(np.float32, self.probes * 6 * n * n * 4).reshape(self.probes, 6, n, n, 4)

    def read_depths(self) -> list[np.ndarray]:
        """Per view (H, W) float32, read back from the GPU; the render must have been asked for depth."""
        self.wait()
        if self.depth is None:
            raise ValueError("this frame has no depth: render(batch, depth=True) writes it")
        return self._split(self.depth.read(np.float32, self.pixels), 1)

    def read_behinds(self) -> list[np.ndarray]:
        """Per view (H, W, 4) float32, the BEHIND layer of a render given a depth cut (render(cut=...))."""
        self.wait()
        if self.behind is None:
            raise ValueError("this frame has no BEHIND layer: render(batch, cut=...) writes it")
        return self._split(self.behind.read(np.float32, self.pixels * 4), 4)


class RenderResult:
    """What render() returns: the frame, and (once the GPU is done: reading these waits) the GPU time per stage
    (timestamp queries), the (tile, splat) pairs rasterised and the host wall time of the render."""

    def __init__(self, frame: GpuFrame, t0: float) -> None:
        self.frame, self._t0 = frame, t0
        self._timings: dict[str, float] = {}
        self._instances, self._wall_ms = 0, 0.0

    def _finished(self, timings: dict[str, float], instances: int) -> None:
        self._timings, self._instances = timings, instances
        self._wall_ms = (time.perf_counter() - self._t0) * 1e3

    @property
    def timings_ms(self) -> dict[str, float]:
        self.frame.renderer.resolve(self)
        return self._timings

    @property
    def instances(self) -> int:
        self.frame.renderer.resolve(self)
        return self._instances

    @property
    def wall_ms(self) -> float:
        self.frame.renderer.resolve(self)
        return self._wall_ms

    @cached_property
    def images(self) -> list[np.ndarray]:
        """Per view (H, W, 4) float32: premultiplied linear RGB, alpha = coverage (read back on first use)."""
        return self.frame.read_images()

    @cached_property
    def depths(self) -> list[np.ndarray]:
        """Per view (H, W): view-space z of what is seen, 0: none (renders asked with depth=True)."""
        return self.frame.read_depths()

    @cached_property
    def behinds(self) -> list[np.ndarray]:
        """Per view (H, W, 4) float32: the BEHIND layer of a render given a depth cut (``images`` is FRONT)."""
        return self.frame.read_behinds()


@dataclass
class CameraFrame:
    """What SplatRenderer.render_camera gives back, on the host (float32, rows from the top).

    ``front``, ``behind``: (H, W, 4) premultiplied linear RGB and alpha (coverage) of the splats nearer than the
    cut and of the rest, each composited front to back among its own (``behind`` is 0 without a cut). A mesh image
    ``mesh`` (premultiplied RGBA, whose surface is what the cut gave) composites as
    ``front + (1 - front.a) * (mesh + (1 - mesh.a) * behind)``. ``depth``: (H, W) the coverage-weighted distance
    along the view axis of FRONT over BEHIND (0: no splat), None when not asked. ``timings``: GPU ms per stage
    (timestamp queries, where the device has them) and "wall", the host's ms for the whole call. ``kernels``: the
    raster and emit kernels that drew it, and why (renderer.batch_kernels)."""
    front: np.ndarray
    behind: np.ndarray
    depth: np.ndarray | None
    timings: dict[str, float]
    kernels: dict[str, str]


def view_values(v, tile_base: int = 0, pixel_base: int = 0) -> dict:
    """The values of one View as the shaders read them, by VIEW_ROWS' component names (core/vk/constants.py)."""
    tx, ty = v.tiles
    fw, fh = v.grid
    if not (0 <= v.x0 and v.x0 + v.width <= fw and 0 <= v.y0 and v.y0 + v.height <= fh):
        raise ValueError(f"view window {v.width}x{v.height} at ({v.x0}, {v.y0}) is outside its {fw}x{fh} frame")
    return {"right": v.right, "tan_x": v.tan_x, "down": v.down, "tan_y": v.tan_y, "forward": v.forward,
            "width": v.width, "height": v.height, "tiles_x": tx, "first_tile": tile_base,
            "first_pixel": pixel_base, "tiles_y": ty, "x0": v.x0, "y0": v.y0,
            "cx": v.cx, "cy": v.cy, "frame_width": fw, "frame_height": fh}


def _view_plan() -> tuple[tuple[tuple[str, np.ndarray], ...], np.ndarray]:
    """Where each View component goes among VIEW_ROWS' words (a name repeated over components: a vector's), and
    which words are uint32 (uvec4 rows): made once, so packing a view is a few assignments."""
    where: dict[str, list[int]] = {}
    uint = np.zeros(VIEW_BYTES // 4, bool)
    for i, (_, kind, parts) in enumerate(VIEW_ROWS):
        for j, name in enumerate(parts.split()):
            if name != "-":
                where.setdefault(name, []).append(4 * i + j)
        uint[4 * i:4 * i + 4] = kind.startswith("u")
    return tuple((n, np.array(w)) for n, w in where.items()), uint


_VIEW_PLAN, _VIEW_UINT = _view_plan()


def pack_view(values: dict) -> np.ndarray:
    """One View struct's bytes (VIEW_BYTES) as 4-byte words: each VIEW_ROWS row's components from ``values``
    (a name repeated over components takes a vector), float rows as float32, uvec4 rows as uint32."""
    row = np.zeros(VIEW_BYTES // 4)
    for name, words in _VIEW_PLAN:
        row[words] = values[name]
    out = row.astype(np.float32).view(np.uint32)
    out[_VIEW_UINT] = row[_VIEW_UINT].astype(np.uint32)
    return out


def _views_buffer_data(batch: ViewBatch) -> tuple[np.ndarray, int, int]:
    """(the views' packed words, total tiles, total pixels). A batch's views are often the very tuple an earlier
    batch had (ViewBatch.cubemap keeps one per face size): its packing is kept with it (_PACKED), since packing
    six views was about 1 ms of a GPU bake's host time."""
    views = batch.views
    kept = _PACKED.get(id(views))
    if kept is not None and kept[0] is views:
        return kept[1]
    if len(views) > MAX_VIEWS:
        raise ValueError(f"a batch holds at most {MAX_VIEWS} views, got {len(views)}")
    rows = []
    tile_base = pixel_base = 0
    for v in views:
        rows.append(pack_view(view_values(v, tile_base, pixel_base)))
        tx, ty = v.tiles
        tile_base += tx * ty
        pixel_base += v.width * v.height
    out = np.concatenate(rows), tile_base, pixel_base
    out[0].flags.writeable = False
    if len(_PACKED) >= 32:  # cameras make new views each frame: start again (a cube's six repack in microseconds)
        _PACKED.clear()
    _PACKED[id(views)] = (views, out)  # the tuple is held with it, so its id is not reused meanwhile
    return out


_PACKED: dict[int, tuple] = {}


def _refs(held: dict, name: str) -> int:
    return sys.getrefcount(held[name])


# What _refs says of an array nothing but a dict holds, measured the same way (what getrefcount counts of a
# function's own references differs between Python versions).
_REFS_UNHELD = _refs({"a": np.empty(0)}, "a")


def cut_pixels(batch: ViewBatch, cut) -> np.ndarray:
    """The depth cut of render(cut=...) as the raster reads it: float32, the views' pixels one after another.
    ``cut``: per view an (H, W) array (one array for a one-view batch) of distances along the view axis, +inf where
    no mesh is seen; NaN is refused (say +inf for "no mesh")."""
    if batch.n_probes != 1:
        raise ValueError(f"a depth cut is for a batch of views from one origin (a camera), not {batch.n_probes} "
                         "probes")
    views = batch.views
    cuts = [cut] if len(views) == 1 and not isinstance(cut, (list, tuple)) else list(cut)
    if len(cuts) != len(views):
        raise ValueError(f"a depth cut needs one (H, W) array per view: {len(views)} views, {len(cuts)} arrays")
    out = []
    for i, (v, c) in enumerate(zip(views, cuts)):
        a = np.asarray(c, np.float32)
        if a.shape != (v.height, v.width):
            raise ValueError(f"depth cut of view {i} has shape {a.shape}; the view renders {v.height}x{v.width} "
                             "(rows x columns; a render border's window, not the whole frame)")
        if np.isnan(a.min()):  # a reduction (min keeps NaN), not an (H, W) mask a frame
            raise ValueError(f"depth cut of view {i} holds NaN at {int(np.isnan(a).sum())} pixels: give +inf where "
                             "no mesh is seen")
        out.append(a.reshape(-1))
    return out[0] if len(out) == 1 else np.concatenate(out)  # a camera's one view: no copy


class SplatRenderer:
    """Holds one scene on the GPU. ``render(batch)`` draws a pinhole view or a whole cubemap in one go.

    ``ctx`` is the Vulkan context to use (default: the shared one, core.vk.get_context()). ``with
    SplatRenderer(scene, ctx) as r:`` frees its GPU memory when the block ends; so does ``close()``.
    ``lod``: True builds the scene's level of detail (or pass a LodTree built before) and uploads all its nodes;
    renders then take ``lod_k`` (0: every splat, as without one).
    """

    def __init__(self, scene: SplatScene, ctx=None, near: float = DEFAULT_NEAR, lod: bool | LodTree = False) -> None:
        self.ctx = ctx or get_context()
        self.scene_count = scene.count
        # The colour rule (core/colour.py), applied in gs_preprocess; may be changed later: it is a push constant,
        # so a new rule records new commands and uploads nothing.
        self.colour_space = check_colour_space(scene.colour_space)
        self.lod: LodTree | None = (lod if isinstance(lod, LodTree) else build_lod(scene)) if lod else None
        if self.lod is not None:
            if self.lod.leaves != scene.count:
                raise ValueError(f"the level of detail was built for {self.lod.leaves:,} splats, not {scene.count:,}")
            scene = self.lod.scene  # every node is uploaded; scene_count stays the splats'
        self.sh_k = scene.sh.shape[1]
        self.near = near
        self.generation = 0
        self.last_frame: GpuFrame | None = None  # the latest render's frame (valid until the next render)
        self._pending: tuple | None = None  # the render submitted and not yet waited for (render(wait=False))
        self._owned: list = []  # every GPU object this renderer made, destroyed by close()
        self._programs: dict[tuple, Program] = {}
        # Per batch shape, the (instances, cut nodes) its recordings are sized for (_caps): learnt from its first
        # render, grown when a frame outgrows them, so a small face after a large one does not sort its capacity.
        self._budgets: dict[tuple, tuple[int, int]] = {}
        self._min_chunks: dict[tuple, int] = {}  # per batch shape, the chunks the loop limit asked for (LOOP_PAIRS)
        # The most instances a group of each batch shape drew, and per probe for each probe shape (_presize)
        self._needed: dict[tuple, int] = {}
        self._per_probe: dict[tuple, float] = {}
        self._frame: dict[str, Buffer] = {}  # frame buffers, grown to the largest batch so far and kept
        self._host: dict[str, np.ndarray] = {}  # render_camera's last arrays (_host_array)
        self._sorted_depth: tuple[Buffer, Buffer] | None = None  # where the depth sort leaves its result
        self.kernels: dict[str, str] = {}  # the last recording's raster and emit kernels, and why (batch_kernels)
        try:
            n = max(1, scene.count)
            buf = self._buffer
            self.pos_op, self.scale, self.rot = buf(n * 16, "pos_op"), buf(n * 16, "scale"), buf(n * 16, "rot")
            self.sh = buf(n * self.sh_k * 12, "sh")
            # in tie order (render/upload.py): the GPU's splat i is the scene's (or the tree's node) order[i]
            self.sh_splat_major = (not self.ctx.is_cpu) if SH_SPLAT_MAJOR is None else bool(SH_SPLAT_MAJOR)
            up = gpu_splats(scene, self.sh_splat_major)
            self.upload_order = up.order.astype(np.uint32)  # kept for the renderer's life: 4 bytes a splat
            if scene.count:
                self.pos_op.write(up.pos_op)
                self.scale.write(up.scale)
                self.rot.write(up.rot)
                self.sh.write(up.sh)
            del up
            self.count = buf(16, "count")
            self.n_count = buf(16, "n_count")  # pairs of a full group, of the last group
            self._n_count = None  # (probes of a full group, of the last) it holds
            self.views = buf(MAX_VIEWS * VIEW_BYTES, "views")
            self.no_depth = buf(16, "no-depth")  # bound where depth is not written
            if self.lod is not None:
                self.lod_words = buf(n * 8, "lod")
                self.lod_words.write(self.lod.words()[self.upload_order])
                self.cut_sorter = None
            self.nodes = n  # splats, or every node of the level of detail: what one probe's pairs run over
            self.slots = 0  # probes the pair buffers hold (a group)
            self.cut_capacity = 0
            self._ensure_slots(1)
            self.drawn = self.scene_count  # splats (or nodes of the cut) the last render drew (per group, at most)
            self.capacity = 0
            self.tile_sorter = None
            self._ensure_capacity(max(1 << 16, 4 * (self.cut_capacity if self.lod is not None else n)))
        except BaseException:
            self.close()  # a failure partway (out of memory) leaves nothing on the GPU
            raise

    def read_depth_order(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """The first ``count`` entries of the last render's depth sort (of its last group of probes): their keys and
        the scene's splat (or the tree's node) each one is, for tests of the tie rule."""
        if self._sorted_depth is None:
            raise RuntimeError("read_depth_order: nothing was rendered yet")
        keys, vals = self._sorted_depth
        return keys.read(np.uint32, count), self.upload_order[vals.read(np.uint32, count) % self.nodes]

    def _own(self, obj):
        self._owned.append(obj)
        return obj

    def _buffer(self, nbytes: int, name: str) -> Buffer:
        return self._own(Buffer(self.ctx, nbytes, name))

    def _drop(self, obj) -> None:
        if obj is not None:
            obj.destroy()
            self._owned.remove(obj)

    _PAIR_BUFFERS = ("prepared", "tile_count", "depth_key", "depth_val", "rects", "offsets", "scanner",
                     "depth_sorter", "sort_key", "sort_val", "lod_scanner")

    def _ensure_slots(self, slots: int) -> None:
        """Per-pair buffers for ``slots`` probes of a group (recordings that used smaller ones become invalid)."""
        if slots <= self.slots:
            return
        for name in self._PAIR_BUFFERS:
            self._drop(getattr(self, name, None))
            setattr(self, name, None)
        old_slots, self.slots = self.slots, int(slots)
        m, buf = self.nodes * self.slots, self._buffer
        self.prepared = buf(m * PREP * 16, "prepared")
        self.tile_count = buf(m * 4, "tile_count")
        self.depth_key, self.depth_val = buf(m * 4, "depth_key"), buf(m * 4, "depth_val")
        self.rects = buf(m * MAX_VIEWS * 8, "rects")  # tile rectangle per pair and view
        self.offsets = buf(m * 4, "offsets")
        self.scanner = self._own(Scanner(self.ctx, m))
        if self.lod is None:
            self.depth_sorter = self._own(RadixSorter(self.ctx, m))
            self._drop(getattr(self, "cut_sorter", None))  # a single view's compaction, made again when asked for
            self.cut_sorter, self.cut_capacity = None, 0
        else:
            self.sort_key, self.sort_val = buf(m * 4, "lod-sort-key"), buf(m * 4, "lod-sort-val")
            self.lod_scanner = self._own(Scanner(self.ctx, m))
            # A probe's cut is a small part of the tree: the stages after the compaction (depth sort, counts, emit)
            # are sized for the cut, from the previous frame, and a frame whose cut outgrew them is drawn again.
            per_probe = self.cut_capacity // old_slots if old_slots else max(1 << 16, self.scene_count // 8)
            self._grow_cut(per_probe * self.slots)

    def held_bytes(self) -> int:
        """GPU bytes of what batches grow: a group's pair buffers, the instance list and the frame buffers."""
        pair = PAIR_BYTES_LOD if self.lod is not None else PAIR_BYTES
        return (self.nodes * self.slots * pair + self.capacity * INSTANCE_BYTES
                + sum(b.nbytes for b in self._frame.values()))

    def trim(self, keep_within: float = 0.0) -> None:
        """Give back what a batch of many probes grew (pair buffers for a group, the instance list, the frame
        buffers: the batch's image and its chunks' partial images) and keep what one probe needs: a renderer kept
        between bakes (Blender's splat cache) then holds no more than before its batch. The next render re-records
        its program and makes its frame buffers again (their size, not their contents, is what a render reuses).
        ``keep_within``: nothing is given back while held_bytes() is within this share of the device's largest
        heap (BAKE_KEEP_SHARE)."""
        self.resolve()
        if keep_within > 0:
            from ..limits import device_local_bytes
            if self.held_bytes() <= keep_within * device_local_bytes(self.ctx):
                return
        self.generation += 1  # the last frame's pairs are gone
        for b in self._frame.values():
            self._drop(b)
        self._frame.clear()
        self._host.clear()
        for name in self._PAIR_BUFFERS + ("inst_key", "inst_val", "owners", "tile_sorter", "cut_sorter"):
            self._drop(getattr(self, name, None))
            setattr(self, name, None)
        self.slots = self.capacity = self.cut_capacity = 0
        self._ensure_slots(1)
        self._ensure_capacity(max(1 << 16, 4 * (self.cut_capacity if self.lod is not None else self.nodes)))

    def _ensure_capacity(self, need: int) -> None:
        if need <= self.capacity:
            return
        for name in ("inst_key", "inst_val", "owners", "tile_sorter"):
            self._drop(getattr(self, name, None))
        self.capacity = int(need)
        self.inst_key = self._buffer(self.capacity * 4, "inst_key")
        self.inst_val = self._buffer(self.capacity * 4, "inst_val")
        self.owners = self._buffer((self.capacity // 256 + 2) * 4, "emit-owners")  # a splat per 256 slots
        self.tile_sorter = self._own(RadixSorter(self.ctx, self.capacity))

    def _compacts(self, batch: ViewBatch) -> bool:
        """Whether ``batch``'s drawn pairs are packed before the depth sort: a level of detail's cut, or a single
        view (COMPACT_VIEWS)."""
        return self.lod is not None or (COMPACT_VIEWS and len(batch.views) == 1 and batch.n_probes == 1)

    def _ensure_compact(self) -> None:
        """A single view's compaction without a level of detail: sorted for every splat it could draw (one probe's
        pairs), so a frame never outgrows it; each shape's budget (_caps) trims what its recordings sort."""
        m = self.nodes
        if self.lod is not None or (self.cut_sorter is not None and self.cut_capacity == m):
            return
        buf = self._buffer
        if self.sort_key is None:
            self.sort_key, self.sort_val = buf(m * 4, "compact-sort-key"), buf(m * 4, "compact-sort-val")
            self.lod_scanner = self._own(Scanner(self.ctx, m))
        self._drop(self.cut_sorter)
        self.cut_capacity = m
        self.cut_sorter = self._own(RadixSorter(self.ctx, m))

    def _grow_cut(self, need: int) -> None:
        self._drop(self.cut_sorter)
        self.cut_capacity = int(min(self.lod.count * self.slots, need))
        self.cut_sorter = self._own(RadixSorter(self.ctx, self.cut_capacity, short_lists=True))

    def _frame_buffer(self, name: str, nbytes: int) -> Buffer:
        """The named frame buffer, at least ``nbytes`` (grown by 1.5x when too small, never shrunk)."""
        b = self._frame.get(name)
        if b is None or b.nbytes < nbytes:
            self._drop(b)
            b = self._frame[name] = self._buffer(max(nbytes, int(b.nbytes * 1.5) if b is not None else 0), name)
        return b

    def render_probes(self, origins, face_size: int, lod_k: float = 0.0, timestamps: bool = False,
                      wait: bool = True) -> RenderResult:
        """Cubemaps of ``face_size``^2 faces at every row of ``origins`` (N, 3), in one submission that shares
        the uploaded splats. The frame holds probe after probe, six faces each (GpuFrame.read_probes(), or
        probe.gpu_filters.filter_probes for their irradiance); each equals ``render(ViewBatch.cubemap(origin,
        face_size))`` of its own position (see the module's docstring). ``lod_k``: as render's, each probe its
        own cut."""
        return self.render(ViewBatch.cubemaps(origins, face_size), timestamps=timestamps, wait=wait, lod_k=lod_k)

    def render(self, batch: ViewBatch, timestamps: bool = False, depth: bool = False,
               wait: bool = True, lod_k: float = 0.0, cut=None) -> RenderResult:
        """Render ``batch`` into a GpuFrame (RenderResult.frame); ``depth`` also writes the depth image.

        ``cut`` (a batch of views from one origin, not probes): per view an (H, W) array, the distance along the
        view axis of the mesh surface each pixel sees (+inf where none; one array for a one-view batch). The frame
        then holds two layers, FRONT (``images``) with the contributions nearer than the cut and BEHIND
        (``behinds``) with the rest, each composited front to back among its own; a caller composites a mesh
        between them: front + (1 - front.a) (mesh + (1 - mesh.a) behind) (render_camera).

        ``lod_k`` (a renderer built with a level of detail): draw the cut of threshold lod_k x the batch's pixel
        angle, each node once its cell spans at most lod_k pixels; 0 draws every splat.

        ``wait=False`` returns once the render is submitted: a filter given the frame is then queued behind it
        and the host waits once for both (GpuFrame.wait() settles the render, and re-draws it in the rare case
        its instance list outgrew the capacity).
        """
        t0 = time.perf_counter()
        if lod_k and self.lod is None:
            raise ValueError("render(lod_k=...) needs a renderer built with a level of detail "
                             "(SplatRenderer(..., lod=True))")
        if not (lod_k >= 0 and np.isfinite(lod_k)):
            raise ValueError(f"lod_k {lod_k!r} must be 0 (every splat) or a positive number of pixels")
        self.resolve()  # the previous render reads the views and origins written below
        view_data, total_tiles, total_pixels = _views_buffer_data(batch)
        probes = batch.n_probes
        cut_data = None if cut is None else cut_pixels(batch, cut)
        layers = cut_data is not None
        if probes > 1:
            check_probes_fit(self.ctx, probes, batch.views[0].width)
        group = probes_per_group(self.ctx, self.nodes, probes, self.lod is not None) if probes > 1 else 1
        if group * total_tiles >= MAX_GROUP_TILES:
            group = max(1, (MAX_GROUP_TILES - 1) // total_tiles)
        if depth and group < probes:
            raise ValueError(f"depth of {probes} probes does not fit one group of this device ({group}): "
                             "render them without depth, or fewer at a time")
        self._ensure_slots(group)
        self._presize(batch, float(lod_k), group)
        if self._compacts(batch):
            self._ensure_compact()
        last = probes - (-(-probes // group) - 1) * group
        self.views.write(view_data)
        if self._n_count != (group, last):  # a single probe's render uploads nothing more than it did
            self.n_count.write(np.array([self.nodes * group, self.nodes * last, 0, 0], np.uint32))
            self._n_count = (group, last)
        origins = self._frame_buffer("origins", probes * 16)
        origins.write(np.concatenate([batch.origins, np.zeros((probes, 1))], 1).astype(np.float32))
        self.generation += 1
        args = (batch, total_tiles, total_pixels, timestamps, depth, layers, float(lod_k), group)
        prog = self._program(*args)
        if layers:
            self._frame["cut"].write(cut_data)
        frame = self.last_frame = GpuFrame(self, batch, self._frame["image"], self._frame["depth"] if depth else None,
                                           self.generation, self._frame["behind"] if layers else None)
        result = RenderResult(frame, t0)
        prog.start()
        self._pending = (prog, result, args)
        if wait:
            self.resolve()
        return result

    def render_camera(self, batch: ViewBatch, cut=None, depth: bool = True, timestamps: bool = True,
                      lod_k: float = 0.0) -> CameraFrame:
        """A camera frame for a final render, arrays in and arrays out (as gsplat's ``rasterization``): ``batch`` one
        view (ViewBatch.camera: lens shift, render border), ``cut`` None or the (H, W) float32 distance along the
        view axis of the mesh surface each pixel sees (+inf where none; the window's pixels for a border), and a
        CameraFrame of FRONT, BEHIND (render(cut=...); without a cut read-only zeros), the depth and the GPU timings
        back. A frame whose images this device cannot hold is refused first, naming the size that fits
        (check_camera_fits). The arrays are the caller's while it holds them (or a view of them); ones it let go are
        read into by a later frame (_host_array), so hold the array, not a raw pointer into it."""
        t0 = time.perf_counter()
        if batch.n_probes != 1 or len(batch.views) != 1:
            raise ValueError(f"render_camera draws one camera view; this batch has {batch.n_probes} origin(s) and "
                             f"{len(batch.views)} views (render() takes any batch)")
        v = batch.views[0]
        check_camera_fits(self.ctx, v.width, v.height)
        res = self.render(batch, timestamps=timestamps, depth=depth, lod_k=lod_k, cut=cut)
        frame, px, hw = res.frame, v.width * v.height, (v.height, v.width)
        frame.wait()
        front = frame.image.read(np.float32, px * 4, out=self._host_array("front", hw + (4,)))
        # Without a cut BEHIND is zero: one read-only zero array per size, shared by such frames (np.zeros cost
        # 3.4 ms a 1080p frame on an H100's host: freed pages coming back are cleared again)
        behind = (frame.behind.read(np.float32, px * 4, out=self._host_array("behind", hw + (4,))) if cut is not None
                  else self._zeros(front.shape))
        d = frame.depth.read(np.float32, px, out=self._host_array("depth", hw)) if depth else None
        timings = dict(res.timings_ms)
        timings["wall"] = (time.perf_counter() - t0) * 1e3
        return CameraFrame(front, behind, d, timings, dict(self.kernels))

    def _zeros(self, shape: tuple[int, ...]) -> np.ndarray:
        """A read-only float32 zero array of ``shape``, kept for the next frame of that size."""
        z = self._host.get("zeros")
        if z is None or z.shape != shape:
            z = self._host["zeros"] = np.zeros(shape, np.float32)
            z.flags.writeable = False
        return z

    def _host_array(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """A float32 array for render_camera to read ``name`` into: the one it gave back last time once nothing
        else holds it (no caller, no view of it: a view holds its base), else a new one, kept for next time. Read
        into memory written before, a 1080p frame's 41 MB cost no page faults (the readback's host time: a copy
        into fresh pages is several times one into used ones)."""
        held = self._host
        if name in held and held[name].shape == shape and _refs(held, name) == _REFS_UNHELD:  # (no local name on it)
            return held[name]
        a = held[name] = np.empty(shape, np.float32)
        return a

    def resolve(self, result: RenderResult | None = None) -> bool:
        """Finish the submitted render, if one is in flight; True when it was drawn again, with room for more
        instances or, on a CPU device, in more chunks (LOOP_PAIRS) (see render's ``wait``)."""
        pending = getattr(self, "_pending", None)
        if pending is None or (result is not None and pending[1] is not result):
            return False
        self._pending = None
        prog, result, args = pending
        timings = prog.wait()
        redrawn = False
        n_groups = -(-args[0].n_probes // args[-1])
        batch, *_, lod_k, group = args
        shape = self._shape(batch, lod_k, group)
        while True:
            # per group: [0] pairs kept, [1] pairs wanted, [2] nodes in the cut
            counts = self._frame["group_counts"].read(np.uint32, 4 * n_groups).reshape(n_groups, 4)
            needed, total = int(counts[:, 1].max()), int(counts[:, 1].sum())
            self._needed[shape] = max(self._needed.get(shape, 0), needed)
            key = self._probe_shape(batch, lod_k)
            self._per_probe[key] = max(self._per_probe.get(key, 0.0), needed / group)
            pairs_cap, cut_cap = self._caps(shape)
            compacts = self._compacts(batch)
            if compacts:
                self.drawn = int(counts[:, 2].max())
            if compacts and self.drawn > cut_cap:  # the cut outgrew its sort: nothing after it counts
                if self.drawn > self.cut_capacity:  # (a level of detail's: a single view's holds every pair)
                    self._grow_cut(int(self.drawn * 1.25) + 1024)
                self._budgets[shape] = (pairs_cap, budget_for(self.drawn))
            elif needed > pairs_cap:
                if needed > self.capacity:
                    self._ensure_capacity(min(int(needed * 1.25) + 1024, self._check_instances(needed, batch)))
                self._budgets[shape] = (budget_for(needed), cut_cap)
            else:
                if shape not in self._budgets:  # its first frame: later ones are sized for what it drew
                    self._budgets[shape] = (budget_fit(needed, pairs_cap),
                                            budget_fit(self.drawn, cut_cap) if compacts else cut_cap)
                chunks = self._loop_chunks(prog, int(counts[:, 3].max()))
                if chunks is None:
                    break
                self._min_chunks[shape] = chunks
            prog = self._program(*args)
            timings = prog.run()
            redrawn = True
        result._finished(timings, total)
        return redrawn

    def _check_instances(self, needed: int, batch: ViewBatch) -> int:
        """The most (tile, splat) instances one storage binding holds; refuses a frame that needs more
        (limits.TooBig, naming the share of its size that would fit: instances grow about as its pixels)."""
        most = _binding_limit(self.ctx) // 4
        if needed <= most:
            return most
        from ..limits import TooBig
        f = (most / needed) ** 0.5
        v = max(batch.views, key=lambda x: x.width * x.height)
        raise TooBig("resolution", v.width,
                     f"this {v.width}x{v.height} frame of {self.scene_count:,} splats has {needed:,} (tile, splat) "
                     f"pairs, more than {self.ctx.device_name} holds in one buffer ({most:,}): render "
                     f"{int(v.width * f)}x{int(v.height * f)} or smaller ({100 * f:.0f}% of this size), or the frame "
                     "in parts with render borders (ViewBatch.camera's window)")

    def _loop_chunks(self, prog: Program, deepest: int) -> int | None:
        """More chunks for a frame whose deepest raster workgroup took more pairs than this device's loops run
        (LOOP_PAIRS, CPU devices only), or None when it did not, or when no more fit in CHUNK_BYTES (then it warns)."""
        limit = LOOP_PAIRS[prog.raster_kernel]
        if not self.ctx.is_cpu or deepest <= limit:
            return None
        want = -(-deepest * prog.chunks // limit)
        if want > prog.max_chunks:
            if prog.max_chunks <= prog.chunks:
                warnings.warn(f"a tile holds {deepest * prog.chunks:,} splats, more than this CPU device's shader "
                              f"loops run in {prog.max_chunks} chunks: its image leaves the farthest out",
                              RuntimeWarning, stacklevel=4)  # render() or GpuFrame.wait()'s caller
                return None
            return prog.max_chunks
        return want

    @staticmethod
    def _shape(batch: ViewBatch, lod_k: float = 0.0, group: int = 1) -> tuple:
        """What sets a render's instance and cut counts, short of where its probes are."""
        return (tuple((v.width, v.height) for v in batch.views), batch.n_probes, group, float(batch.pixel_angle),
                batch.dilation, lod_k)

    @staticmethod
    def _probe_shape(batch: ViewBatch, lod_k: float = 0.0) -> tuple:
        """_shape without the batch's size: what sets one probe's instances."""
        return (tuple((v.width, v.height) for v in batch.views), float(batch.pixel_angle), batch.dilation, lod_k)

    def _presize(self, batch: ViewBatch, lod_k: float, group: int) -> None:
        """Room in the instance list, before recording, for what this batch shape drew before (a new shape: what
        its probes drew in other batches, per probe). A frame learns that it outgrew the list only once drawn, and
        is then drawn again: after trim() (a renderer kept between bakes) the first batch of every bake was drawn
        twice (the sample room's light volume on an H100, buffers given back before each bake: 149-180 ms and 7
        submissions a bake without this, 131-152 ms and 3 with it; volume_bench, 2026-12-06)."""
        need = self._needed.get(self._shape(batch, lod_k, group))
        if need is None:
            per = self._per_probe.get(self._probe_shape(batch, lod_k))
            need = None if per is None else per * group
        if need:
            want = int(need * 1.25) + 1024  # the margin a frame that outgrew the list is drawn again with
            if want > self.capacity:
                self._ensure_capacity(min(want, _binding_limit(self.ctx) // 4))

    def _caps(self, shape: tuple) -> tuple[int, int]:
        """(instances, cut nodes) that recordings of ``shape`` sort and emit: the learnt budget, within the
        buffers' capacities. Counts past them are caught after the frame (resolve), which draws it again."""
        pairs, cut = self._budgets.get(shape, (self.capacity, self.cut_capacity))
        return min(pairs, self.capacity), min(cut, self.cut_capacity)

    def _program(self, batch: ViewBatch, total_tiles: int, total_pixels: int, timestamps: bool,
                 depth: bool, layers: bool = False, lod_k: float = 0.0, group: int = 1) -> Program:
        shape = self._shape(batch, lod_k, group)
        caps, min_chunks = self._caps(shape), self._min_chunks.get(shape, 1)
        kernels = batch_kernels(self.ctx, batch, total_tiles, layers)
        what = (shape, bool(batch.energy_preserving), batch.sort, bool(timestamps), bool(depth),
                check_colour_space(self.colour_space), PLANE_FORMS, kernels["raster"], kernels["emit"],
                self._compacts(batch))
        key = what + (self.capacity, self.cut_capacity, caps, min_chunks)  # and the sizes it was recorded for
        prog = self._programs.pop(key, None)
        if prog is not None and not prog.valid:
            prog.close()
            prog = None
        if prog is None:
            # the same work recorded for other sizes is never asked for again (budgets and capacities only follow
            # what frames drew): it goes now, not after newer shapes pushed the search's out (Auto's bake
            # re-recorded four programs a bake on an H100, 3.5 ms each)
            for old in [k for k in self._programs if k[:len(what)] == what]:
                self._programs.pop(old).close()
            # (a kernel's descriptor pool that fills meanwhile is retired, not reset: the recording stays valid)
            prog = self._record(batch, total_tiles, total_pixels, timestamps, depth, lod_k, group, caps, kernels,
                                min_chunks, layers)
            while len(self._programs) >= PROGRAMS_KEPT:  # the least recently used goes
                self._programs.pop(next(iter(self._programs))).close()
        self._programs[key] = prog
        self.chunks = prog.chunks
        self.kernels = kernels  # the last recording's raster and emit kernels, and why (batch_kernels)
        return prog

    def _record(self, batch: ViewBatch, total_tiles: int, total_pixels: int, timestamps: bool,
                depth: bool, lod_k: float, group: int, caps: tuple[int, int], kernels: dict[str, str],
                min_chunks: int = 1, layers: bool = False) -> Program:
        """One submission: the probes in groups of ``group``, one group after another through the same pair
        buffers (a batch of one probe, or one that fits, is a single group). ``total_tiles`` / ``total_pixels``
        are one probe's; ``caps`` the (instances, cut nodes) it sorts (_caps); ``kernels`` its raster and emit
        (batch_kernels); ``min_chunks`` what the loop limit asked for (_loop_chunks); ``layers``: a depth cut's
        FRONT and BEHIND (one group: cameras, not probes)."""
        c, nv, probes = self.ctx, len(batch.views), batch.n_probes
        n_groups = -(-probes // group)
        tree = self.lod
        image = self._frame_buffer("image", probes * total_pixels * 16)
        depth_buf = self._frame_buffer("depth", probes * total_pixels * 4) if depth else self.no_depth
        origins = self._frame["origins"]
        counts = self._frame_buffer("group_counts", n_groups * 16)
        ranges = self._frame_buffer("ranges", (group * total_tiles + 1) * 8)  # + the missed-tile key's run
        split = n_groups > 1  # each group rasters into its own image and origins, copied from / to the batch's
        if layers and split:
            raise ValueError("a depth cut is for a batch of views from one origin, not probes")
        g_image = self._frame_buffer("group_image", group * total_pixels * 16) if split else image
        g_origin = self._frame_buffer("group_origins", group * 16) if split else origins
        # the same chunks for every group (the last, smaller one included): partial sized for a full group
        n_layers = 2 if layers else 1
        chunk_bytes = group * total_pixels * (16 + (4 if depth else 0)) * n_layers
        fit = chunks_that_fit(chunk_bytes)
        chunks = chunks_max = min(max(raster_chunks(total_tiles, group, chunk_bytes, target_groups(c)), min_chunks),
                                  fit)
        if chunks_max > 1:
            partial = self._frame_buffer("partial", group * total_pixels * 16 * chunks_max)
            partial_depth = (self._frame_buffer("partial_depth", group * total_pixels * 4 * n_layers * chunks_max)
                             if depth else self.no_depth)
            if layers:
                partial_behind = self._frame_buffer("partial_behind", total_pixels * 16 * chunks_max)
        if layers:
            behind = self._frame_buffer("behind", total_pixels * 16)
            cut_buf = self._frame_buffer("cut", total_pixels * 4)
        kernel = kernels["raster"]
        rec = Recorder(c, timestamps=timestamps, reusable=True)
        rec.fill(image, 0, probes * total_pixels * 16)
        if layers:
            rec.fill(behind, 0, total_pixels * 16)
        if depth:
            rec.fill(depth_buf, 0, probes * total_pixels * 4)
        rec.timestamp("clear")
        # Stage stamps for up to a few groups (a query pool holds MAX_STAMPS); beyond, one stamp per group.
        stamp = rec.timestamp if n_groups <= 6 else (lambda _label: None)
        for k in range(n_groups):
            gp = min(group, probes - k * group)  # probes in this group
            count_index = 0 if gp == group else 1  # n_count: pairs of a full group, of the last one
            tiles, pixels = gp * total_tiles, gp * total_pixels
            if split:
                rec.copy(origins, g_origin, gp * 16, k * group * 16)
            rec.fill(self.count)
            rec.fill(ranges, 0, (tiles + 1) * 8)
            n = tree.count if tree is not None else self.scene_count
            inst_val = self.inst_val  # (no splats: the raster's ranges are empty and it reads none)
            if n:
                inst_val = self._record_sort_emit(rec, batch, g_origin, gp, n, count_index, tiles, lod_k, stamp, caps,
                                                  kernels["emit"])
            raster_buffers = [self.views, ranges, inst_val, self.prepared, partial if chunks > 1 else g_image,
                              partial_depth if chunks > 1 else depth_buf, self.count]
            if layers:
                raster_buffers += [cut_buf, partial_behind if chunks > 1 else behind]
            rec.dispatch(KERNELS[kernel], raster_buffers,
                         groups(total_tiles * chunks, 1, c) + (gp,), n_views=nv, total_tiles=total_tiles,
                         chunks=chunks, total_pixels=pixels, write_depth=int(depth), plane_forms=int(PLANE_FORMS))
            if chunks > 1 and layers:
                rec.dispatch(KERNELS["gs_merge_cut"], [partial, g_image, partial_depth, depth_buf, partial_behind,
                                                       behind], groups(pixels, 256, c),
                             chunks=chunks, total_pixels=pixels, write_depth=int(depth))
            elif chunks > 1:
                rec.dispatch(KERNELS["gs_merge"], [partial, g_image, partial_depth, depth_buf], groups(pixels, 256, c),
                             chunks=chunks, total_pixels=pixels, write_depth=int(depth))
            stamp("raster")
            if split:
                rec.copy(g_image, image, pixels * 16, 0, k * group * total_pixels * 16)
            rec.copy(self.count, counts, 16, 0, k * 16)
            if n_groups > 6:
                rec.timestamp("probes")
        prog = rec.program()
        prog.chunks, prog.max_chunks = chunks_max, fit  # what resolve's loop limit asks more of
        prog.raster_kernel = kernel  # whose LOOP_PAIRS it asks against
        return prog

    def _record_sort_emit(self, rec: Recorder, batch: ViewBatch, origins: Buffer, probes: int, n: int,
                          count_index: int, tiles: int, lod_k: float, stamp, caps: tuple[int, int],
                          emit: str) -> Buffer:
        """preprocess -> [the cut's compaction] -> depth sort -> counts -> emit -> tile sort -> ranges, for the
        (probe, splat) pairs of ``probes`` probes at ``origins``; returns the buffer the tile-sorted pairs' splats
        are in (the sorts leave their results where their last pass wrote them)."""
        c, tree, nv = self.ctx, self.lod, len(batch.views)
        capacity, cut_capacity = caps
        compact = self._compacts(batch)
        grid = (dict(lod=1, lod_tau=lod_k * batch.pixel_angle, lod_cell=tree.cell1, lod_ox=tree.origin[0],
                     lod_oy=tree.origin[1], lod_oz=tree.origin[2]) if tree is not None else
                dict(lod=0, lod_tau=0.0, lod_cell=0.0, lod_ox=0.0, lod_oy=0.0, lod_oz=0.0))
        rec.dispatch(KERNELS["gs_preprocess"],
                     [self.pos_op, self.scale, self.rot, self.sh, self.views, self.prepared, self.tile_count,
                      self.depth_key, self.depth_val, self.rects, origins,
                      self.lod_words if tree is not None else self.no_depth,
                      self.offsets],  # Live: written only when compacting (offsets are free until emit)
                     (probes,) + groups(n, 256, c),  # x: the probe, (y, z): the block of splats
                     n=n, dilation_angle=batch.dilation, near=self.near, sh_k=self.sh_k, n_views=nv,
                     energy_preserving=int(batch.energy_preserving), srgb=int(self.colour_space == "srgb"),
                     sort_order=int(batch.sort), sh_splat_major=int(self.sh_splat_major), compact=int(compact),
                     **grid)
        stamp("preprocess")
        pairs = n * probes
        if compact:
            # the cut (or the view's drawn pairs), packed in storage order (the upload's tie order): its count stays
            # on the GPU (live_total[0]); a single view's packing is timed with its depth sort
            live_total = self.lod_scanner.record(rec, self.offsets, pairs)
            rec.dispatch(KERNELS["gs_lod_compact"], [self.depth_key, self.offsets, self.sort_key, self.sort_val],
                         groups(pairs, 256, c), n=pairs)
            rec.copy(live_total, self.count, 4, dst_offset=8)  # read back with the pair counts
            if tree is not None:
                stamp("lod_compact")
            keys, vals, sort_count, sorter, count_index = (self.sort_key, self.sort_val, live_total, self.cut_sorter,
                                                           0)
            pairs = cut_capacity  # from here on only the cut's entries
        else:
            keys, vals, sort_count, sorter = self.depth_key, self.depth_val, self.n_count, self.depth_sorter
        # the sorted pairs stay where the last pass wrote them (three passes: the sorter's scratch), no copy back
        keys, vals = sorter.record(rec, keys, vals, sort_count, count_index, DEPTH_KEY_BITS,
                                   stamps="sort_depth" if PROFILE_SORTS else None, n=pairs, in_place=False)
        self._sorted_depth = (keys, vals)
        stamp("sort_depth")
        rec.dispatch(KERNELS["gs_gather_counts"], [keys, vals, self.tile_count, self.offsets, sort_count],
                     groups(pairs, 256, c), n=pairs, count_index=count_index)
        total_buf = self.scanner.record(rec, self.offsets, pairs)
        emit_buffers = [self.views, keys, vals, self.offsets, total_buf, self.inst_key, self.inst_val, self.count,
                        self.prepared, self.rects, self.owners]
        if emit == "gs_emit_per_splat":
            rec.dispatch(KERNELS["gs_emit_per_splat"], emit_buffers, groups(pairs, 256, c), n=pairs,
                         capacity=capacity, n_views=nv, n_tiles=tiles)
        else:
            rec.dispatch(KERNELS["gs_emit_owners"], [self.offsets, total_buf, self.owners], groups(pairs, 256, c),
                         n=pairs, capacity=capacity)
            rec.dispatch(KERNELS["gs_emit"], emit_buffers, groups(capacity, 256, c), n=pairs, capacity=capacity,
                         n_views=nv, n_tiles=tiles)
        stamp("emit")
        # `tiles` is the key of instances whose tile the footprint missed: the sort drops them (count[0] becomes
        # the pairs kept), so its second pass, ranges and raster never see them
        inst_key, inst_val = self.tile_sorter.record(
            rec, self.inst_key, self.inst_val, self.count, 0, max(1, int(tiles - 1).bit_length()), drop_key=tiles,
            stamps="sort_tiles" if PROFILE_SORTS else None, n=capacity, in_place=False)
        stamp("sort_tiles")
        rec.dispatch(KERNELS["gs_ranges"], [inst_key, self.count, self._frame["ranges"]], groups(capacity, 256, c))
        stamp("ranges")
        return inst_val

    def close(self) -> None:
        self._pending = None
        for prog in self._programs.values():
            prog.close()
        self._programs.clear()
        while self._owned:
            self._owned.pop().destroy()
        self._frame.clear()
        self._host.clear()
        self.generation += 1  # frames of this renderer are stale now

    def __enter__(self) -> "SplatRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_cubemap(scene: SplatScene, origin, face_size: int, renderer: SplatRenderer | None = None,
                   timestamps: bool = False) -> tuple[np.ndarray, RenderResult]:
    """(6, N, N, 4) float32 cube faces (+X, -X, +Y, -Y, +Z, -Z) from ``origin``, and the render details."""
    if renderer is not None:
        res = renderer.render(ViewBatch.cubemap(origin, face_size), timestamps)
        return np.stack(res.images), res
    with SplatRenderer(scene) as r:
        res = r.render(ViewBatch.cubemap(origin, face_size), timestamps)
        return np.stack(res.images), res
