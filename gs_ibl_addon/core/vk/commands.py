"""Recording and submitting: the Recorder (one-shot: ``with Recorder(ctx) as r:`` submits and waits) and the
Program (a recording submitted again and again). Command buffers, fences and query pools come from the context's
pools and go back to them; GPU timings come from timestamp queries.
"""
from __future__ import annotations

import threading
from typing import Sequence

import numpy as np

from .context import VulkanContext
from .kernels import Kernel
from .pipelines import Buffer, get_pipeline

_NO_TIMEOUT = 0xFFFFFFFFFFFFFFFF


def groups(n_items: int, group_size: int, ctx: VulkanContext) -> tuple[int, int]:
    """Workgroup counts (x, y) covering ``n_items``; shaders linearise with gl_WorkGroupID.y * gl_NumWorkGroups.x."""
    g = max(1, -(-int(n_items) // group_size))
    mx = min(ctx.max_workgroups[0], 65535)
    if g <= mx:
        return g, 1
    return mx, -(-g // mx)


MAX_STAMPS = 64


def _take_query_pool(ctx: VulkanContext):
    if ctx._free_queries:
        return ctx._free_queries.pop()
    vk = ctx.vk
    qpci = vk.VkQueryPoolCreateInfo(queryType=vk.VK_QUERY_TYPE_TIMESTAMP, queryCount=MAX_STAMPS)
    return vk.vkCreateQueryPool(ctx.device, qpci, None)


def _take_command_buffer(ctx: VulkanContext):
    if ctx._free_cmds:
        return ctx._free_cmds.pop()
    vk = ctx.vk
    cbai = vk.VkCommandBufferAllocateInfo(commandPool=ctx.command_pool, level=vk.VK_COMMAND_BUFFER_LEVEL_PRIMARY,
                                          commandBufferCount=1)
    return vk.vkAllocateCommandBuffers(ctx.device, cbai)[0]


class Submission:
    """One vkQueueSubmit of the command buffers queued since the last (context.queued), with its fence; ``wait()``
    may be called by each of their owners, the first waits."""

    def __init__(self, ctx: VulkanContext, fence) -> None:
        self.ctx, self.fence, self.done = ctx, fence, False
        self._lock = threading.Lock()

    def wait(self) -> None:
        with self._lock:
            if self.done:
                return
            vk, ctx = self.ctx.vk, self.ctx
            fences = [self.fence]
            try:
                vk.vkWaitForFences(ctx.device, 1, fences, vk.VK_TRUE, _NO_TIMEOUT)
            finally:
                vk.vkResetFences(ctx.device, 1, fences)
                with ctx.lock:
                    ctx._free_fences.append(self.fence)
                self.done = True


def flush(ctx: VulkanContext) -> Submission | None:
    """Submit every command buffer queued (Program.start, _submit) in one vkQueueSubmit, in the order queued: the
    queue runs them in that order, each opening with a full barrier. None when nothing was queued."""
    vk = ctx.vk
    with ctx.lock:
        queued, ctx.queued = ctx.queued, []
        if not queued:
            return None
        fence = (ctx._free_fences.pop() if ctx._free_fences
                 else vk.vkCreateFence(ctx.device, vk.VkFenceCreateInfo(), None))
        cmds = [cmd for cmd, _ in queued]
        si = vk.VkSubmitInfo(commandBufferCount=len(cmds), pCommandBuffers=cmds)
        sis = [si]
        try:
            vk.vkQueueSubmit(ctx.queue, 1, sis, fence)
        except BaseException:
            ctx._free_fences.append(fence)
            raise
        ctx.stats.submits += 1
        sub = Submission(ctx, fence)
        for _, owner in queued:
            if owner is not None:
                owner._submission = sub
        return sub


def _submit(ctx: VulkanContext, cmd) -> Submission:
    """Submit ``cmd`` after whatever is queued, in the same vkQueueSubmit, without waiting."""
    with ctx.lock:
        ctx.queued.append((cmd, None))
        return flush(ctx)


def _submit_and_wait(ctx: VulkanContext, cmd) -> None:
    _submit(ctx, cmd).wait()


def _read_stamps(ctx: VulkanContext, query_pool, labels: list[str]) -> dict[str, float]:
    vk = ctx.vk
    n = len(labels)
    if query_pool is None or n < 2:
        return {}
    data = vk.ffi.new("uint64_t[]", n)
    vk.vkGetQueryPoolResults(ctx.device, query_pool, 0, n, n * 8, data, 8,
                             vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT)
    ms = np.frombuffer(vk.ffi.buffer(data, n * 8), np.uint64).astype(np.float64) * ctx.timestamp_period_ns * 1e-6
    out: dict[str, float] = {}
    for i in range(1, n):
        out[labels[i]] = out.get(labels[i], 0.0) + float(ms[i] - ms[i - 1])
    out["total"] = float(ms[-1] - ms[0])
    ctx.stats.gpu_ms += out["total"]
    return out


class Recorder:
    """Records dispatches into one command buffer; ``with Recorder(ctx) as r:`` submits and waits on exit.

    A full compute barrier opens the recording (earlier submissions' writes are visible) and follows every
    dispatch/copy/fill, so consecutive stages see each other's writes. ``timestamp(label)`` marks the end of a
    stage; ``timings_ms`` holds stage durations after submission. ``program()`` instead of submitting keeps the
    recording as a Program to submit any number of times.
    """

    def __init__(self, ctx: VulkanContext, timestamps: bool = False, reusable: bool = False) -> None:
        vk = self.vk = ctx.vk
        self.ctx = ctx
        self.reusable = reusable
        ctx.reset_descriptor_pools()  # full pools nothing uses any more are reset here, between recordings
        self.pools: dict[int, object] = {}  # descriptor pools whose sets this recording binds (context.pool_users)
        self.buffers: dict[int, Buffer] = {}  # every buffer the recording uses (a Program checks they live)
        self.cmd = _take_command_buffer(ctx)
        flags = 0 if reusable else vk.VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT
        cbbi = vk.VkCommandBufferBeginInfo(flags=flags)
        vk.vkBeginCommandBuffer(self.cmd, cbbi)
        self.labels: list[str] = []
        self.timings_ms: dict[str, float] = {}
        self.query_pool = None
        self._barrier()
        self._forced = not timestamps and ctx.stamp_all  # profiling: stamped for stats.gpu_ms, not reported
        if (timestamps or self._forced) and ctx.timestamps_supported:
            self.query_pool = _take_query_pool(ctx)
            vk.vkCmdResetQueryPool(self.cmd, self.query_pool, 0, MAX_STAMPS)
            self.timestamp("start")

    def _barrier(self) -> None:
        vk = self.vk
        access = (vk.VK_ACCESS_SHADER_READ_BIT | vk.VK_ACCESS_SHADER_WRITE_BIT | vk.VK_ACCESS_TRANSFER_READ_BIT
                  | vk.VK_ACCESS_TRANSFER_WRITE_BIT)
        mb = vk.VkMemoryBarrier(srcAccessMask=access, dstAccessMask=access)
        mbs = [mb]
        stages = vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | vk.VK_PIPELINE_STAGE_TRANSFER_BIT
        vk.vkCmdPipelineBarrier(self.cmd, stages, stages, 0, 1, mbs, 0, None, 0, None)

    def _hold(self, pool) -> None:
        if id(pool) not in self.pools:
            self.pools[id(pool)] = pool
            with self.ctx.lock:
                self.ctx.pool_users[id(pool)] = self.ctx.pool_users.get(id(pool), 0) + 1

    def _use(self, *buffers: Buffer) -> None:
        for b in buffers:
            self.buffers[b.serial] = b

    def dispatch(self, kernel: Kernel, buffers: Sequence[Buffer], group_count: tuple[int, ...] | int,
                 **push) -> None:
        """Run ``kernel`` over ``group_count`` workgroups (x, y[, z]) with ``buffers`` bound in its table order;
        ``push`` names every push-constant field of the kernel (kernels.py). Kernels that batch several probes
        read the probe from one workgroup axis (render/renderer.py render_probes, probe/gpu_filters.py)."""
        vk = self.vk
        counts = (group_count,) if isinstance(group_count, int) else tuple(group_count)
        gx, gy, gz = counts + (1,) * (3 - len(counts))
        if gx == 0 or gy == 0 or gz == 0:
            return
        pipeline = get_pipeline(self.ctx, kernel)
        data = kernel.pack(push)
        vk.vkCmdBindPipeline(self.cmd, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.handle)
        sets = [pipeline.descriptor_set(buffers)]
        self._hold(pipeline.pool)
        self._use(*buffers)
        vk.vkCmdBindDescriptorSets(self.cmd, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.layout, 0, 1, sets, 0, None)
        if data:
            raw = vk.ffi.new("char[]", data)
            vk.vkCmdPushConstants(self.cmd, pipeline.layout, vk.VK_SHADER_STAGE_COMPUTE_BIT, 0, len(data), raw)
            del raw
        vk.vkCmdDispatch(self.cmd, gx, gy, gz)
        self._barrier()

    def fill(self, buffer: Buffer, value: int = 0, nbytes: int | None = None) -> None:
        size = buffer.nbytes if nbytes is None else (int(nbytes) + 3) // 4 * 4
        if size == 0:
            return
        self._use(buffer)
        self.vk.vkCmdFillBuffer(self.cmd, buffer.handle, 0, size, value & 0xFFFFFFFF)
        self._barrier()

    def copy(self, src: Buffer, dst: Buffer, nbytes: int, src_offset: int = 0, dst_offset: int = 0) -> None:
        vk = self.vk
        self._use(src, dst)
        regions = [vk.VkBufferCopy(srcOffset=src_offset, dstOffset=dst_offset, size=nbytes)]
        vk.vkCmdCopyBuffer(self.cmd, src.handle, dst.handle, 1, regions)
        self._barrier()

    def timestamp(self, label: str) -> None:
        if self.query_pool is None or len(self.labels) >= MAX_STAMPS:
            return
        self.vk.vkCmdWriteTimestamp(self.cmd, self.vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                                    self.query_pool, len(self.labels))
        self.labels.append(label)

    def _end(self) -> None:
        if self._forced:
            self.timestamp("end")
        self.vk.vkEndCommandBuffer(self.cmd)

    def submit(self) -> dict[str, float]:
        ctx = self.ctx
        self._end()
        try:
            _submit_and_wait(ctx, self.cmd)
            stamps = _read_stamps(ctx, self.query_pool, self.labels)
            self.timings_ms = {} if self._forced else stamps
        finally:
            self._give_back()
        return self.timings_ms

    def program(self) -> "Program":
        """End the recording and keep it: Program.run() submits it again and again."""
        self._end()
        prog = Program(self.ctx, self.cmd, self.query_pool, list(self.labels), list(self.buffers.values()),
                       self.pools)
        prog.forced = self._forced
        self.cmd = self.query_pool = None
        self.pools = {}  # the program's now
        return prog

    def _give_back(self) -> None:
        ctx = self.ctx
        release_pools(ctx, self.pools)
        self.pools = {}
        if self.cmd is not None:
            self.vk.vkResetCommandBuffer(self.cmd, 0)
            ctx._free_cmds.append(self.cmd)
            self.cmd = None
        if self.query_pool is not None:
            ctx._free_queries.append(self.query_pool)
            self.query_pool = None

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.submit()
        elif self.cmd is not None:
            self.vk.vkEndCommandBuffer(self.cmd)
            self._give_back()


class Program:
    """A recorded command buffer, submitted again with ``run()`` (waits; returns GPU timings per stage).

    It stays valid while every buffer it uses lives (``valid``); its owner re-records when not. Its descriptor
    sets live as long as it does (the pools they came from count it as a user: context.pool_users). ``close()``
    returns its command buffer to the context.
    """

    def __init__(self, ctx: VulkanContext, cmd, query_pool, labels: list[str], buffers: list[Buffer],
                 pools: dict[int, object]) -> None:
        self.ctx, self.cmd, self.query_pool, self.labels = ctx, cmd, query_pool, labels
        self.buffers, self.pools = buffers, pools

    @property
    def valid(self) -> bool:
        return (self.cmd is not None and self.ctx.device is not None
                and all(b.handle is not None for b in self.buffers))

    def run(self) -> dict[str, float]:
        self.start()
        return self.wait()

    def start(self) -> None:
        """Queue for submission without waiting: programs started one after another go to the GPU together, in
        one vkQueueSubmit, at the first wait (flush), and run in the order started, each opening with a full
        barrier, so a program started next sees this one's writes. ``wait()`` before reading what it wrote."""
        if not self.valid:
            raise RuntimeError("recorded program is stale (a buffer it uses was freed); record it again")
        if self.running:
            raise RuntimeError("program started twice without a wait")
        with self.ctx.lock:
            self._started, self._submission = True, None
            self.ctx.queued.append((self.cmd, self))

    def wait(self) -> dict[str, float]:
        """Wait for the program from start() (submitting what is queued, itself included); returns its GPU
        timings per stage."""
        if not self.running:
            raise RuntimeError("program waited on without a start")
        if self._submission is None:
            flush(self.ctx)
        self._submission.wait()
        self._started, self._submission = False, None
        stamps = _read_stamps(self.ctx, self.query_pool, self.labels)
        return {} if getattr(self, "forced", False) else stamps

    @property
    def running(self) -> bool:
        return getattr(self, "_started", False)

    def close(self) -> None:
        ctx = self.ctx
        if self.running and ctx.device is not None:
            self.wait()
        if self.cmd is not None and ctx.device is not None:
            ctx.vk.vkResetCommandBuffer(self.cmd, 0)
            ctx._free_cmds.append(self.cmd)
            if self.query_pool is not None:
                ctx._free_queries.append(self.query_pool)
        self.cmd = self.query_pool = None
        self.buffers = []
        release_pools(ctx, self.pools)
        self.pools = {}


def release_pools(ctx: VulkanContext, pools: dict[int, object]) -> None:
    """A recording or program is done with the descriptor pools it bound sets of (context.pool_users)."""
    with ctx.lock:
        for key in pools:
            left = ctx.pool_users.get(key, 0) - 1
            if left > 0:
                ctx.pool_users[key] = left
            else:
                ctx.pool_users.pop(key, None)
