"""The GPU splat renderer: scene buffers uploaded once, then any batch of views rendered in one submission.

Stages (each a compute dispatch, timed with timestamp queries when asked):
  preprocess   per splat, once for all views: cull, ray-evaluation frame, SH colour, tiles touched, depth key
  sort_depth   radix sort of splats by distance from the origin (one order serves all six cube faces)
  emit         prefix sum of tile counts in depth order, then one (tile, splat) instance per touched tile
  sort_tiles   stable radix sort of instances by tile id (depth order survives inside each tile)
  ranges       each tile's run of instances
  raster       one workgroup per tile of every view, front-to-back compositing with early termination
The instance list is sized from the previous frame; if a frame needs more, it is re-rendered once with room.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..scene import SplatScene
from ..vk import Buffer, Recorder, get_context
from ..vk.compute import groups, pack
from .gpu_sort import RadixSorter, Scanner
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


DEPTH_KEY_BITS = 24  # distance float bits >> 8 (DEPTH_KEY_SHIFT in shaders/splat_common.glsl)


@dataclass
class RenderResult:
    images: list[np.ndarray]  # per view (H, W, 4) float32: premultiplied linear RGB, alpha = coverage
    depths: list[np.ndarray] = field(default_factory=list)  # per view (H, W): view-space z of what is seen, 0: none
    timings_ms: dict[str, float] = field(default_factory=dict)  # GPU time per stage (timestamp queries)
    instances: int = 0  # (tile, splat) pairs rasterised
    wall_ms: float = 0.0


def _views_buffer_data(batch: ViewBatch) -> tuple[np.ndarray, int, int]:
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
    """Holds one scene on the GPU. ``render(batch)`` draws a pinhole view or a whole cubemap in one go."""

    def __init__(self, scene: SplatScene, ctx=None, near: float = DEFAULT_NEAR) -> None:
        self.ctx = ctx or get_context()
        self.scene_count = scene.count
        self.sh_k = scene.sh.shape[1]
        self.near = near
        n = max(1, scene.count)
        c = self.ctx
        self.pos_op = Buffer(c, n * 16, "pos_op")
        self.scale = Buffer(c, n * 16, "scale")
        self.rot = Buffer(c, n * 16, "rot")
        self.sh = Buffer(c, n * self.sh_k * 12, "sh")
        if scene.count:
            self.pos_op.write(np.concatenate([scene.positions, scene.opacities[:, None]], 1).astype(np.float32))
            self.scale.write(np.concatenate([scene.scales, np.zeros((scene.count, 1))], 1).astype(np.float32))
            self.rot.write(scene.rotations.astype(np.float32))
            # coefficient-major (K, 3, N): see sh_coeff() in shaders/gs_preprocess.comp
            self.sh.write(np.ascontiguousarray(np.transpose(scene.sh, (1, 2, 0)), np.float32))
        self.prepared = Buffer(c, n * 80, "prepared")  # PREP = 5 vec4 per splat (shaders/splat_common.glsl)
        self.tile_count = Buffer(c, n * 4, "tile_count")
        self.depth_key = Buffer(c, n * 4, "depth_key")
        self.depth_val = Buffer(c, n * 4, "depth_val")
        self.rects = Buffer(c, n * 6 * 8, "rects")  # tile rectangle per splat and view (up to six)
        self.offsets = Buffer(c, n * 4, "offsets")
        self.count = Buffer(c, 16, "count")
        self.n_count = Buffer(c, 16, "n_count")
        self.n_count.write(np.array([scene.count, 0, 0, 0], np.uint32))
        self.depth_sorter = RadixSorter(c, n)
        self.scanner = Scanner(c, n)
        self.capacity = 0
        self._frame: dict = {}
        self._ensure_capacity(max(1 << 16, 4 * n))

    def _ensure_capacity(self, need: int) -> None:
        if need <= self.capacity:
            return
        for name in ("inst_key", "inst_val"):
            old = getattr(self, name, None)
            if old is not None:
                old.destroy()
        if getattr(self, "tile_sorter", None) is not None:
            self.tile_sorter.destroy()
        self.capacity = int(need)
        self.inst_key = Buffer(self.ctx, self.capacity * 4, "inst_key")
        self.inst_val = Buffer(self.ctx, self.capacity * 4, "inst_val")
        self.tile_sorter = RadixSorter(self.ctx, self.capacity)

    def _ensure_frame(self, total_tiles: int, total_pixels: int, view_bytes: int) -> None:
        f = self._frame
        if f.get("tiles") != total_tiles or f.get("pixels") != total_pixels:
            for b in f.get("buffers", ()):
                b.destroy()
            ranges = Buffer(self.ctx, (total_tiles + 1) * 8, "ranges")  # + the missed-tile key's run
            image = Buffer(self.ctx, total_pixels * 16, "image")
            depth = Buffer(self.ctx, total_pixels * 4, "depth")
            views = Buffer(self.ctx, max(view_bytes, 6 * 80), "views")
            chunks = raster_chunks(total_tiles)
            partial = Buffer(self.ctx, total_pixels * 16 * chunks if chunks > 1 else 16, "raster-partials")
            partial_depth = Buffer(self.ctx, total_pixels * 4 * chunks if chunks > 1 else 16, "raster-partial-depth")
            self._frame = {"tiles": total_tiles, "pixels": total_pixels, "ranges": ranges, "image": image,
                           "depth": depth, "views": views, "chunks": chunks, "partial": partial,
                           "partial_depth": partial_depth,
                           "buffers": (ranges, image, depth, views, partial, partial_depth)}

    def render(self, batch: ViewBatch, timestamps: bool = False) -> RenderResult:
        t0 = time.perf_counter()
        view_data, total_tiles, total_pixels = _views_buffer_data(batch)
        self._ensure_frame(total_tiles, total_pixels, view_data.nbytes)
        fr = self._frame
        fr["views"].write(view_data)
        for _attempt in range(2):
            timings = self._record_and_submit(batch, total_tiles, timestamps)
            needed = int(self.count.read(np.uint32, 2)[1])  # [0] pairs kept, [1] pairs wanted
            if needed <= self.capacity:
                break
            self._ensure_capacity(int(needed * 1.25) + 1024)
        image = fr["image"].read(np.float32, total_pixels * 4)
        depth = fr["depth"].read(np.float32, total_pixels)
        images, depths, off = [], [], 0
        for v in batch.views:
            npx = v.width * v.height
            images.append(image[off * 4:(off + npx) * 4].reshape(v.height, v.width, 4))
            depths.append(depth[off:off + npx].reshape(v.height, v.width))
            off += npx
        return RenderResult(images, depths, timings, needed, (time.perf_counter() - t0) * 1e3)

    def _record_and_submit(self, batch: ViewBatch, total_tiles: int, timestamps: bool) -> dict[str, float]:
        c, fr = self.ctx, self._frame
        n = self.scene_count
        o = batch.origin.astype(np.float32)
        nv = len(batch.views)
        with Recorder(c, timestamps=timestamps) as rec:
            rec.fill(self.count)
            rec.fill(fr["ranges"])
            rec.fill(fr["image"], 0, total_tiles and fr["pixels"] * 16)
            rec.fill(fr["depth"], 0, total_tiles and fr["pixels"] * 4)
            rec.timestamp("clear")
            if n:
                rec.dispatch(c.pipeline("gs_preprocess", 10, 36),
                             [self.pos_op, self.scale, self.rot, self.sh, fr["views"], self.prepared, self.tile_count,
                              self.depth_key, self.depth_val, self.rects], groups(n, 256, c),
                             pack("fffIffIII", *o, n, batch.pixel_angle, self.near, self.sh_k, nv,
                                  int(batch.energy_preserving)))
                rec.timestamp("preprocess")
                self.depth_sorter.record(rec, self.depth_key, self.depth_val, self.n_count, 0, DEPTH_KEY_BITS)
                rec.timestamp("sort_depth")
                rec.dispatch(c.pipeline("gs_gather_counts", 4, 4),
                             [self.depth_key, self.depth_val, self.tile_count, self.offsets], groups(n, 256, c),
                             pack("I", n))
                total_buf = self.scanner.record(rec, self.offsets, n)
                rec.dispatch(c.pipeline("gs_emit", 10, 16),
                             [fr["views"], self.depth_key, self.depth_val, self.offsets, total_buf, self.inst_key,
                              self.inst_val, self.count, self.prepared, self.rects],
                             groups(self.capacity, 256, c), pack("IIII", n, self.capacity, nv, total_tiles))
                rec.timestamp("emit")
                # tile ids run to total_tiles inclusive: that one is the key of instances whose tile was missed
                bits = max(1, int(total_tiles).bit_length())
                self.tile_sorter.record(rec, self.inst_key, self.inst_val, self.count, 0, bits)
                rec.timestamp("sort_tiles")
                rec.dispatch(c.pipeline("gs_ranges", 3, 0), [self.inst_key, self.count, fr["ranges"]],
                             groups(self.capacity, 256, c))
                rec.timestamp("ranges")
            chunks, npx = fr["chunks"], fr["pixels"]
            rec.dispatch(c.pipeline("gs_raster", 6, 16),
                         [fr["views"], fr["ranges"], self.inst_val, self.prepared,
                          fr["partial"] if chunks > 1 else fr["image"],
                          fr["partial_depth"] if chunks > 1 else fr["depth"]],
                         groups(total_tiles * chunks, 1, c), pack("IIII", nv, total_tiles, chunks, npx))
            if chunks > 1:
                rec.dispatch(c.pipeline("gs_merge", 4, 8),
                             [fr["partial"], fr["image"], fr["partial_depth"], fr["depth"]], groups(npx, 256, c),
                             pack("II", chunks, npx))
            rec.timestamp("raster")
        return rec.timings_ms

    def close(self) -> None:
        for name in ("pos_op", "scale", "rot", "sh", "prepared", "tile_count", "depth_key", "depth_val", "rects", "offsets",
                     "count", "n_count", "inst_key", "inst_val"):
            getattr(self, name).destroy()
        for b in self._frame.get("buffers", ()):
            b.destroy()
        self.depth_sorter.destroy()
        self.tile_sorter.destroy()
        self.scanner.destroy()


def render_cubemap(scene: SplatScene, origin, face_size: int, renderer: SplatRenderer | None = None,
                   timestamps: bool = False) -> tuple[np.ndarray, RenderResult]:
    """(6, N, N, 4) float32 cube faces (+X, -X, +Y, -Y, +Z, -Z) from ``origin``, and the render details."""
    r = renderer or SplatRenderer(scene)
    res = r.render(ViewBatch.cubemap(origin, face_size), timestamps)
    return np.stack(res.images), res
