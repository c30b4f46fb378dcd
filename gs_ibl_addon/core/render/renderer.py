"""The GPU splat renderer: scene buffers uploaded once, then any batch of views rendered in one submission.

``render(batch)`` returns a RenderResult whose ``frame`` (GpuFrame) stays on the GPU: the probe filters take it
as it is, and only what is looked at (``images``, ``depths``) is read back. Depth is written only when asked.
Each batch shape is recorded once into a Program and submitted again for every later render of that shape (the
probe position travels in a buffer), so a render costs the host one submit and one wait.

Stages (each a compute dispatch, timed with timestamp queries when asked):
  preprocess   per splat, once for all views: cull, ray-evaluation frame, SH colour, tiles touched, depth key
  sort_depth   radix sort of splats by distance from the origin (one order serves all six cube faces)
  emit         prefix sum of tile counts in depth order, then one (tile, splat) instance per touched tile
  sort_tiles   stable radix sort of instances by tile id (depth order survives inside each tile)
  ranges       each tile's run of instances
  raster       one workgroup per tile of every view, front-to-back compositing with early termination
The instance list is sized from the previous frame; if a frame needs more, it is re-rendered once with room.

With a level of detail (``SplatRenderer(scene, lod=True)``, render/lod.py) the GPU holds every node of the tree
and ``render(batch, lod_k=k)`` draws the cut of threshold k x pixel angle: preprocess decides per node and flags
the drawn ones, a prefix sum and gs_lod_compact pack them in storage order, and the later stages see only those.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..colour import check_colour_space
from ..scene import SplatScene
from ..vk import Buffer, Program, Recorder, get_context, groups
from ..vk.constants import DEPTH_KEY_BITS, MAX_VIEWS, PREP
from ..vk.kernels import KERNELS
from .gpu_sort import RadixSorter, Scanner
from .lod import LodTree, build_lod
from .splat_math import DEFAULT_NEAR
from .views import ViewBatch

# A 32^2 cubemap has only 24 tiles, too few workgroups for a GPU: below CHUNK_BELOW_TILES tiles each tile's list
# is split into chunks composited in parallel (gs_raster.comp / gs_merge.comp), up to RASTER_TARGET_GROUPS
# workgroups. Chunks give up the early termination of pixels that turned opaque in an earlier chunk, so they only
# pay where tiles are very few: on an H200, for 1M splats, 32 chunks took a 32^2 probe's raster from 2.0 to 1.1 ms,
# while 10 chunks made 64^2 slower than one pass (1.16 vs 0.76 ms) (docs/bench/runs/chunk_experiment.md).
RASTER_TARGET_GROUPS = 1024
MAX_RASTER_CHUNKS = 32
CHUNK_BELOW_TILES = 64


def raster_chunks(total_tiles: int) -> int:
    if total_tiles >= CHUNK_BELOW_TILES:
        return 1
    return int(min(MAX_RASTER_CHUNKS, max(1, RASTER_TARGET_GROUPS // max(1, total_tiles))))


# Benchmarks only: a timestamp after each step of both sorts (labels "<stage>.hist", ".scan", ".scatter").
PROFILE_SORTS = False

PROGRAMS_KEPT = 8  # recorded batch shapes per renderer (a face-size search uses about four)


class StaleFrame(RuntimeError):
    """A GpuFrame read after its renderer rendered again (the frame's buffers now hold the newer image)."""


@dataclass(eq=False)
class GpuFrame:
    """One rendered batch on the GPU: ``image`` holds premultiplied linear RGB + coverage (float32 RGBA) per pixel,
    views one after another (a cubemap: faces +X, -X, +Y, -Y, +Z, -Z, rows top first); ``depth`` the view-space z
    per pixel (0: nothing seen) when the render was asked for it, else None.

    The buffers belong to the renderer and are reused by its next render: a frame is valid until then (reading a
    stale one raises StaleFrame). Filters take it without a host round trip (probe.gpu_filters).
    """
    renderer: "SplatRenderer"
    batch: ViewBatch
    image: Buffer
    depth: Buffer | None
    generation: int

    @property
    def ctx(self):
        return self.renderer.ctx

    @property
    def pixels(self) -> int:
        return sum(v.width * v.height for v in self.batch.views)

    @property
    def face_size(self) -> int:
        """The face size of a cubemap frame (six square views)."""
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
        drawn again (its instance list outgrew the renderer's capacity): work queued on the frame meanwhile saw an
        incomplete image and must run again."""
        self.check()
        return self.renderer.resolve()

    def _split(self, flat: np.ndarray, channels: int) -> list[np.ndarray]:
        out, off = [], 0
        for v in self.batch.views:
            npx = v.width * v.height
            out.append(flat[off * channels:(off + npx) * channels].reshape((v.height, v.width, channels)[:2 + (channels > 1)]))
            off += npx
        return out

    def read_images(self) -> list[np.ndarray]:
        """Per view (H, W, 4) float32, read back from the GPU."""
        self.wait()
        return self._split(self.image.read(np.float32, self.pixels * 4), 4)

    def read_cube(self) -> np.ndarray:
        """A cubemap frame as one (6, N, N, 4) float32 array, read back from the GPU (no per-face copies)."""
        n = self.face_size
        self.wait()
        return self.image.read(np.float32, 6 * n * n * 4).reshape(6, n, n, 4)

    def read_depths(self) -> list[np.ndarray]:
        """Per view (H, W) float32, read back from the GPU; the render must have been asked for depth."""
        self.wait()
        if self.depth is None:
            raise ValueError("this frame has no depth: render(batch, depth=True) writes it")
        return self._split(self.depth.read(np.float32, self.pixels), 1)


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


def _views_buffer_data(batch: ViewBatch) -> tuple[np.ndarray, int, int]:
    if len(batch.views) > MAX_VIEWS:
        raise ValueError(f"a batch holds at most {MAX_VIEWS} views, got {len(batch.views)}")
    rows = []
    tile_base = pixel_base = 0
    for v in batch.views:
        tx, ty = v.tiles
        f = np.zeros(20, np.float32)
        f[0:3], f[3] = v.right, v.tan_x
        f[4:7], f[7] = v.down, v.tan_y
        f[8:11] = v.forward
        u = f.view(np.uint32)
        u[12:16] = (v.width, v.height, tx, tile_base)
        u[16:20] = (pixel_base, ty, 0, 0)
        rows.append(f)
        tile_base += tx * ty
        pixel_base += v.width * v.height
    return np.concatenate(rows), tile_base, pixel_base


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
        self._frame: dict[str, Buffer] = {}  # frame buffers, grown to the largest batch so far and kept
        try:
            n = max(1, scene.count)
            buf = self._buffer
            self.pos_op, self.scale, self.rot = buf(n * 16, "pos_op"), buf(n * 16, "scale"), buf(n * 16, "rot")
            self.sh = buf(n * self.sh_k * 12, "sh")
            if scene.count:
                self.pos_op.write(np.concatenate([scene.positions, scene.opacities[:, None]], 1).astype(np.float32))
                self.scale.write(np.concatenate([scene.scales, np.zeros((scene.count, 1))], 1).astype(np.float32))
                self.rot.write(scene.rotations.astype(np.float32))
                # coefficient-major (K, 3, N): see sh_coeff() in shaders/gs_preprocess.comp
                self.sh.write(np.ascontiguousarray(np.transpose(scene.sh, (1, 2, 0)), np.float32))
            self.prepared = buf(n * PREP * 16, "prepared")
            self.tile_count = buf(n * 4, "tile_count")
            self.depth_key, self.depth_val = buf(n * 4, "depth_key"), buf(n * 4, "depth_val")
            self.rects = buf(n * MAX_VIEWS * 8, "rects")  # tile rectangle per splat and view
            self.offsets = buf(n * 4, "offsets")
            self.count = buf(16, "count")
            self.n_count = buf(16, "n_count")
            self.n_count.write(np.array([scene.count, 0, 0, 0], np.uint32))
            self.origin = buf(16, "origin")
            self.views = buf(MAX_VIEWS * 80, "views")
            self.no_depth = buf(16, "no-depth")  # bound where depth is not written
            if self.lod is not None:
                self.lod_words = buf(n * 8, "lod")
                self.lod_words.write(self.lod.words())
                self.sort_key, self.sort_val = buf(n * 4, "lod-sort-key"), buf(n * 4, "lod-sort-val")
                self.lod_scanner = self._own(Scanner(self.ctx, n))
                # A probe's cut is a small part of the tree: the stages after the compaction (depth sort, counts, emit)
                # are sized for the cut, from the previous frame, and a frame whose cut outgrew them is drawn again.
                self.cut_sorter = None
                self._grow_cut(max(1 << 16, self.scene_count // 8))
            self.drawn = self.scene_count  # splats (or nodes of the cut) the last render drew
            self.depth_sorter = self._own(RadixSorter(self.ctx, n)) if self.lod is None else None
            self.scanner = self._own(Scanner(self.ctx, n))
            self.capacity = 0
            self.tile_sorter = None
            self._ensure_capacity(max(1 << 16, 4 * (self.cut_capacity if self.lod is not None else n)))
        except BaseException:
            self.close()  # a failure partway (out of memory) leaves nothing on the GPU
            raise

    def _own(self, obj):
        self._owned.append(obj)
        return obj

    def _buffer(self, nbytes: int, name: str) -> Buffer:
        return self._own(Buffer(self.ctx, nbytes, name))

    def _drop(self, obj) -> None:
        if obj is not None:
            obj.destroy()
            self._owned.remove(obj)

    def _ensure_capacity(self, need: int) -> None:
        if need <= self.capacity:
            return
        for name in ("inst_key", "inst_val", "tile_sorter"):
            self._drop(getattr(self, name, None))
        self.capacity = int(need)
        self.inst_key = self._buffer(self.capacity * 4, "inst_key")
        self.inst_val = self._buffer(self.capacity * 4, "inst_val")
        self.tile_sorter = self._own(RadixSorter(self.ctx, self.capacity))

    def _grow_cut(self, need: int) -> None:
        self._drop(self.cut_sorter)
        self.cut_capacity = int(min(self.lod.count, need))
        self.cut_sorter = self._own(RadixSorter(self.ctx, self.cut_capacity))

    def _frame_buffer(self, name: str, nbytes: int) -> Buffer:
        """The named frame buffer, at least ``nbytes`` (grown by 1.5x when too small, never shrunk)."""
        b = self._frame.get(name)
        if b is None or b.nbytes < nbytes:
            self._drop(b)
            b = self._frame[name] = self._buffer(max(nbytes, int(b.nbytes * 1.5) if b is not None else 0), name)
        return b

    def render(self, batch: ViewBatch, timestamps: bool = False, depth: bool = False,
               wait: bool = True, lod_k: float = 0.0) -> RenderResult:
        """Render ``batch`` into a GpuFrame (RenderResult.frame); ``depth`` also writes the depth image.

        ``lod_k`` (a renderer built with a level of detail): draw the cut of threshold lod_k x the batch's pixel
        angle, each node once its cell spans at most lod_k pixels; 0 draws every splat.

        ``wait=False`` returns once the render is submitted: a filter given the frame is then queued behind it
        and the host waits once for both (GpuFrame.wait() settles the render, and re-draws it in the rare case
        its instance list outgrew the capacity).
        """
        t0 = time.perf_counter()
        if lod_k and self.lod is None:
            raise ValueError("render(lod_k=...) needs a renderer built with a level of detail (SplatRenderer(..., lod=True))")
        if not (lod_k >= 0 and np.isfinite(lod_k)):
            raise ValueError(f"lod_k {lod_k!r} must be 0 (every splat) or a positive number of pixels")
        self.resolve()  # the previous render reads the views and origin written below
        view_data, total_tiles, total_pixels = _views_buffer_data(batch)
        self.views.write(view_data)
        self.origin.write(np.append(batch.origin, 0.0).astype(np.float32))
        self.generation += 1
        prog = self._program(batch, total_tiles, total_pixels, timestamps, depth, float(lod_k))
        frame = self.last_frame = GpuFrame(self, batch, self._frame["image"], self._frame["depth"] if depth else None,
                                           self.generation)
        result = RenderResult(frame, t0)
        prog.start()
        self._pending = (prog, result, (batch, total_tiles, total_pixels, timestamps, depth, float(lod_k)))
        if wait:
            self.resolve()
        return result

    def resolve(self, result: RenderResult | None = None) -> bool:
        """Finish the submitted render, if one is in flight; True when it was drawn again with room for more
        instances (see render's ``wait``)."""
        pending = getattr(self, "_pending", None)
        if pending is None or (result is not None and pending[1] is not result):
            return False
        self._pending = None
        prog, result, args = pending
        timings = prog.wait()
        redrawn = False
        while True:
            counts = self.count.read(np.uint32, 3)  # [0] pairs kept, [1] pairs wanted, [2] nodes in the cut
            needed = int(counts[1])
            if self.lod is not None:
                self.drawn = int(counts[2])
                if self.drawn > self.cut_capacity:  # the cut outgrew its sort: nothing after it counts
                    self._grow_cut(int(self.drawn * 1.25) + 1024)
                elif needed > self.capacity:
                    self._ensure_capacity(int(needed * 1.25) + 1024)
                else:
                    break
            elif needed > self.capacity:
                self._ensure_capacity(int(needed * 1.25) + 1024)
            else:
                break
            timings = self._program(*args).run()
            redrawn = True
        result._finished(timings, needed)
        return redrawn

    def _program(self, batch: ViewBatch, total_tiles: int, total_pixels: int, timestamps: bool,
                 depth: bool, lod_k: float = 0.0) -> Program:
        shape = tuple((v.width, v.height) for v in batch.views)
        key = (shape, float(batch.pixel_angle), bool(batch.energy_preserving), bool(timestamps), bool(depth),
               self.capacity, lod_k, getattr(self, "cut_capacity", 0), check_colour_space(self.colour_space))
        prog = self._programs.pop(key, None)
        if prog is not None and not prog.valid:
            prog.close()
            prog = None
        if prog is None:
            prog = self._record(batch, total_tiles, total_pixels, timestamps, depth, lod_k)
            while len(self._programs) >= PROGRAMS_KEPT:  # the least recently used goes
                self._programs.pop(next(iter(self._programs))).close()
        self._programs[key] = prog
        return prog

    def _record(self, batch: ViewBatch, total_tiles: int, total_pixels: int, timestamps: bool,
                depth: bool, lod_k: float = 0.0) -> Program:
        c, nv = self.ctx, len(batch.views)
        tree = self.lod
        n = tree.count if tree is not None else self.scene_count
        chunks = raster_chunks(total_tiles)
        ranges = self._frame_buffer("ranges", (total_tiles + 1) * 8)
        image = self._frame_buffer("image", total_pixels * 16)
        depth_buf = self._frame_buffer("depth", total_pixels * 4) if depth else self.no_depth
        if chunks > 1:
            partial = self._frame_buffer("partial", total_pixels * 16 * chunks)
            partial_depth = self._frame_buffer("partial_depth", total_pixels * 4 * chunks) if depth else self.no_depth
        rec = Recorder(c, timestamps=timestamps, reusable=True)
        rec.fill(self.count)
        rec.fill(ranges, 0, (total_tiles + 1) * 8)
        rec.fill(image, 0, total_pixels * 16)
        if depth:
            rec.fill(depth_buf, 0, total_pixels * 4)
        rec.timestamp("clear")
        if n:
            grid = (dict(lod=1, lod_tau=lod_k * batch.pixel_angle, lod_cell=tree.cell1, lod_ox=tree.origin[0],
                         lod_oy=tree.origin[1], lod_oz=tree.origin[2]) if tree is not None else
                    dict(lod=0, lod_tau=0.0, lod_cell=0.0, lod_ox=0.0, lod_oy=0.0, lod_oz=0.0))
            rec.dispatch(KERNELS["gs_preprocess"],
                         [self.pos_op, self.scale, self.rot, self.sh, self.views, self.prepared, self.tile_count,
                          self.depth_key, self.depth_val, self.rects, self.origin,
                          self.lod_words if tree is not None else self.no_depth,
                          self.offsets],  # Live: written only with a level of detail (offsets are free until emit)
                         groups(n, 256, c),
                         n=n, pixel_angle=batch.pixel_angle, near=self.near, sh_k=self.sh_k, n_views=nv,
                         energy_preserving=int(batch.energy_preserving), srgb=int(self.colour_space == "srgb"),
                         **grid)
            rec.timestamp("preprocess")
            if tree is not None:
                # the cut, packed in storage order: its count stays on the GPU (first uint of live_total)
                live_total = self.lod_scanner.record(rec, self.offsets, n)
                rec.dispatch(KERNELS["gs_lod_compact"], [self.depth_key, self.offsets, self.sort_key, self.sort_val],
                             groups(n, 256, c), n=n)
                rec.copy(live_total, self.count, 4, dst_offset=8)  # read back with the pair counts
                rec.timestamp("lod_compact")
                keys, vals, sort_count, sorter = self.sort_key, self.sort_val, live_total, self.cut_sorter
                n = self.cut_capacity  # from here on only the cut's entries
            else:
                keys, vals, sort_count, sorter = self.depth_key, self.depth_val, self.n_count, self.depth_sorter
            sorter.record(rec, keys, vals, sort_count, 0, DEPTH_KEY_BITS,
                          stamps="sort_depth" if PROFILE_SORTS else None)
            rec.timestamp("sort_depth")
            rec.dispatch(KERNELS["gs_gather_counts"], [keys, vals, self.tile_count, self.offsets, sort_count],
                         groups(n, 256, c), n=n, count_index=0)
            total_buf = self.scanner.record(rec, self.offsets, n)
            rec.dispatch(KERNELS["gs_emit"],
                         [self.views, keys, vals, self.offsets, total_buf, self.inst_key,
                          self.inst_val, self.count, self.prepared, self.rects],
                         groups(self.capacity, 256, c), n=n, capacity=self.capacity, n_views=nv, n_tiles=total_tiles)
            rec.timestamp("emit")
            # total_tiles is the key of instances whose tile the footprint missed: the sort drops them (count[0]
            # becomes the pairs kept), so the second pass, ranges and raster never see them
            bits = max(1, int(total_tiles - 1).bit_length())
            self.tile_sorter.record(rec, self.inst_key, self.inst_val, self.count, 0, bits, drop_key=total_tiles,
                                    stamps="sort_tiles" if PROFILE_SORTS else None)
            rec.timestamp("sort_tiles")
            rec.dispatch(KERNELS["gs_ranges"], [self.inst_key, self.count, ranges], groups(self.capacity, 256, c))
            rec.timestamp("ranges")
        rec.dispatch(KERNELS["gs_raster"],
                     [self.views, ranges, self.inst_val, self.prepared, partial if chunks > 1 else image,
                      partial_depth if chunks > 1 else depth_buf],
                     groups(total_tiles * chunks, 1, c), n_views=nv, total_tiles=total_tiles, chunks=chunks,
                     total_pixels=total_pixels, write_depth=int(depth))
        if chunks > 1:
            rec.dispatch(KERNELS["gs_merge"], [partial, image, partial_depth, depth_buf], groups(total_pixels, 256, c),
                         chunks=chunks, total_pixels=total_pixels, write_depth=int(depth))
        rec.timestamp("raster")
        self.chunks = chunks
        return rec.program()

    def close(self) -> None:
        self._pending = None
        for prog in self._programs.values():
            prog.close()
        self._programs.clear()
        while self._owned:
            self._owned.pop().destroy()
        self._frame.clear()
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
