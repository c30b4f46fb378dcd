"""Storage buffers, compute pipelines, a command recorder and recorded programs.

The `vulkan` package's trap (shared/NOTES-vulkan-and-gpu.md): cffi frees a temporary struct as soon as Python drops
it, so a nested create-info written inline can hand the driver freed memory. Here every nested struct, array and
string is bound to a local name that lives until the call returns; nowhere else builds create-infos.

Command buffers, fences and query pools come from the context and go back to it after each submission; host
transfers go through the context's two staging buffers and are counted in ``ctx.stats``. A ``Program`` is a
recorded command buffer submitted again and again: what changes between runs lives in buffers, never in the
recording, so a probe's host cost is one submit and one wait.
"""
from __future__ import annotations

import itertools
from typing import Sequence

import numpy as np

from importlib import resources

from .context import VulkanContext, VulkanUnavailable
from .kernels import Kernel

_serial = itertools.count(1)
_NO_TIMEOUT = 0xFFFFFFFFFFFFFFFF
STAGING_MAX = 64 << 20  # the kept staging buffers grow to this at most; larger transfers go in pieces


class Buffer:
    """A storage buffer. Device-local where the device has such memory; mapped directly when it is host-visible.

    ``with Buffer(ctx, n) as b:`` destroys it when the block ends; a pooled buffer (``scratch``) goes back to
    the context's pool instead.
    """

    def __init__(self, ctx: VulkanContext, nbytes: int, name: str = "", pooled: bool = False) -> None:
        vk = ctx.vk
        self.ctx, self.name, self.serial, self.pooled = ctx, name, next(_serial), pooled
        self.nbytes = max(int(nbytes), 16)
        usage = (vk.VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT
                 | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT)
        bci = vk.VkBufferCreateInfo(size=self.nbytes, usage=usage, sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE)
        self.handle = vk.vkCreateBuffer(ctx.device, bci, None)
        req = vk.vkGetBufferMemoryRequirements(ctx.device, self.handle)
        local = vk.VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT
        host = vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | vk.VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
        # Host-visible device-local memory (lavapipe, resizable BAR) avoids staging copies; big buffers on a
        # discrete GPU live in plain device-local memory and go through a staging buffer.
        choices = [local | host, local, host] if self.nbytes <= (256 << 20) or ctx.is_cpu else [local, local | host, host]
        for flags in choices:
            try:
                mtype = ctx.memory_type(req.memoryTypeBits, flags)
            except RuntimeError:
                continue
            mai = vk.VkMemoryAllocateInfo(allocationSize=req.size, memoryTypeIndex=mtype)
            try:
                self.memory = vk.vkAllocateMemory(ctx.device, mai, None)
            except Exception:
                continue
            mflags = ctx.memory_properties.memoryTypes[mtype].propertyFlags
            self.host_visible = bool(mflags & vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT)
            # Reading uncached mapped memory (a GPU's BAR window) crawls; such buffers read through a cached copy.
            self.host_cached = bool(mflags & vk.VK_MEMORY_PROPERTY_HOST_CACHED_BIT)
            break
        else:
            vk.vkDestroyBuffer(ctx.device, self.handle, None)
            raise MemoryError(f"{ctx.device_name}: cannot allocate {self.nbytes / 2**20:.1f} MiB for buffer {name!r}")
        vk.vkBindBufferMemory(ctx.device, self.handle, self.memory, 0)
        self._map = vk.vkMapMemory(ctx.device, self.memory, 0, self.nbytes, 0) if self.host_visible else None

    def write(self, data: np.ndarray | bytes, offset: int = 0) -> None:
        raw = memoryview(np.ascontiguousarray(data)).cast("B") if isinstance(data, np.ndarray) else memoryview(data)
        if offset + raw.nbytes > self.nbytes:
            raise ValueError(f"write of {raw.nbytes} bytes at {offset} overflows buffer {self.name!r} ({self.nbytes})")
        if raw.nbytes == 0:
            return
        stats = self.ctx.stats
        stats.uploads += 1
        stats.upload_bytes += raw.nbytes
        if self._map is not None:
            np.frombuffer(self._map, np.uint8, raw.nbytes, offset)[:] = np.frombuffer(raw, np.uint8)
            return
        with self.ctx.lock:  # through the kept staging buffer, in pieces of at most STAGING_MAX bytes
            stage = staging(self.ctx, min(raw.nbytes, STAGING_MAX), "up")
            for start in range(0, raw.nbytes, STAGING_MAX):
                piece = raw[start:start + STAGING_MAX]
                np.frombuffer(stage._map, np.uint8, piece.nbytes)[:] = np.frombuffer(piece, np.uint8)
                with Recorder(self.ctx) as rec:
                    rec.copy(stage, self, piece.nbytes, dst_offset=offset + start)

    def read(self, dtype=np.uint8, count: int | None = None, offset: int = 0) -> np.ndarray:
        dt = np.dtype(dtype)
        n = (self.nbytes - offset) // dt.itemsize if count is None else int(count)
        nbytes = n * dt.itemsize
        stats = self.ctx.stats
        stats.readbacks += 1
        stats.readback_bytes += nbytes
        # Small reads of mapped memory are direct even when uncached (a few words cost less than a copy).
        if self._map is not None and (self.host_cached or nbytes <= 4096):
            return np.frombuffer(self._map, dtype=dt, count=n, offset=offset).copy()
        out = np.empty(n, dt)
        dst = out.view(np.uint8)
        with self.ctx.lock:
            stage = staging(self.ctx, min(nbytes, STAGING_MAX), "down")
            for start in range(0, nbytes, STAGING_MAX):
                size = min(STAGING_MAX, nbytes - start)
                with Recorder(self.ctx) as rec:
                    rec.copy(self, stage, size, src_offset=offset + start)
                dst[start:start + size] = np.frombuffer(stage._map, np.uint8, size)  # one memcpy
        return out

    @staticmethod
    def staging(ctx: VulkanContext, nbytes: int, cached: bool = False) -> "Buffer":
        """A host-visible transfer buffer (the context keeps two: VulkanContext.staging)."""
        b = Buffer.__new__(Buffer)
        vk = ctx.vk
        b.ctx, b.name, b.serial, b.nbytes, b.pooled = ctx, "staging", next(_serial), max(int(nbytes), 16), False
        bci = vk.VkBufferCreateInfo(size=b.nbytes, sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE,
                                    usage=vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT)
        b.handle = vk.vkCreateBuffer(ctx.device, bci, None)
        req = vk.vkGetBufferMemoryRequirements(ctx.device, b.handle)
        flags = vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | vk.VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
        try:
            mtype = ctx.memory_type(req.memoryTypeBits, flags | (vk.VK_MEMORY_PROPERTY_HOST_CACHED_BIT if cached else 0))
        except RuntimeError:
            mtype = ctx.memory_type(req.memoryTypeBits, flags)
        mai = vk.VkMemoryAllocateInfo(allocationSize=req.size, memoryTypeIndex=mtype)
        b.memory = vk.vkAllocateMemory(ctx.device, mai, None)
        vk.vkBindBufferMemory(ctx.device, b.handle, b.memory, 0)
        b.host_visible = True
        b.host_cached = cached
        b._map = vk.vkMapMemory(ctx.device, b.memory, 0, b.nbytes, 0)
        return b

    @property
    def alive(self) -> bool:
        return self.handle is not None and self.ctx.device is not None

    def destroy(self) -> None:
        vk = self.ctx.vk
        if self.handle is None or self.ctx.device is None:
            return
        if self._map is not None:
            vk.vkUnmapMemory(self.ctx.device, self.memory)
            self._map = None
        vk.vkDestroyBuffer(self.ctx.device, self.handle, None)
        vk.vkFreeMemory(self.ctx.device, self.memory, None)
        self.handle = None

    def close(self) -> None:
        """End of this owner's use: a pooled buffer returns to the context's pool, any other is destroyed."""
        if self.pooled and self.alive:
            self.ctx.release(self)
        else:
            self.destroy()

    def __enter__(self) -> "Buffer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            if not getattr(self, "pooled", False):
                self.destroy()
        except Exception:
            pass


class Pipeline:
    """The compute pipeline of one kernels.Kernel: set 0 = its storage buffers, plus its push-constant block."""

    POOL_SETS = 1024

    def __init__(self, ctx: VulkanContext, kernel: Kernel, spirv: bytes) -> None:
        vk = ctx.vk
        self.ctx, self.kernel, self.name = ctx, kernel, kernel.name
        self.n_buffers, self.push_size = len(kernel.buffers), kernel.push_size
        bindings = [vk.VkDescriptorSetLayoutBinding(binding=i, descriptorType=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                                                    descriptorCount=1, stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT)
                    for i in range(self.n_buffers)]
        dslci = vk.VkDescriptorSetLayoutCreateInfo(bindingCount=len(bindings), pBindings=bindings)
        self.set_layout = vk.vkCreateDescriptorSetLayout(ctx.device, dslci, None)
        set_layouts = [self.set_layout]
        ranges = ([vk.VkPushConstantRange(stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT, offset=0, size=self.push_size)]
                  if self.push_size else [])
        plci = vk.VkPipelineLayoutCreateInfo(setLayoutCount=1, pSetLayouts=set_layouts,
                                             pushConstantRangeCount=len(ranges), pPushConstantRanges=ranges or None)
        self.layout = vk.vkCreatePipelineLayout(ctx.device, plci, None)
        code = bytes(spirv)  # the binding casts pCode from a bytes object itself
        smci = vk.VkShaderModuleCreateInfo(codeSize=len(code), pCode=code)
        self.module = vk.vkCreateShaderModule(ctx.device, smci, None)
        entry = "main"
        stage = vk.VkPipelineShaderStageCreateInfo(stage=vk.VK_SHADER_STAGE_COMPUTE_BIT, module=self.module, pName=entry)
        cpci = vk.VkComputePipelineCreateInfo(stage=stage, layout=self.layout)
        cpcis = [cpci]
        self.handle = vk.vkCreateComputePipelines(ctx.device, None, 1, cpcis, None)[0]
        del code, stage, cpci, cpcis, entry
        pool_sizes = [vk.VkDescriptorPoolSize(type=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                                              descriptorCount=max(1, self.n_buffers) * self.POOL_SETS)]
        dpci = vk.VkDescriptorPoolCreateInfo(maxSets=self.POOL_SETS, poolSizeCount=1, pPoolSizes=pool_sizes)
        self.pool = vk.vkCreateDescriptorPool(ctx.device, dpci, None)
        self._sets: dict[tuple, object] = {}

    def descriptor_set(self, buffers: Sequence[Buffer]):
        vk = self.ctx.vk
        if len(buffers) != self.n_buffers:
            raise ValueError(f"kernel {self.name} binds {self.kernel.buffers}, got {len(buffers)} buffers")
        key = tuple(b.serial for b in buffers)
        ds = self._sets.get(key)
        if ds is not None:
            return ds
        if len(self._sets) >= self.POOL_SETS:
            # Safe for one-shot recordings (every submission waits for completion); recorded programs see the
            # new epoch and re-record.
            vk.vkResetDescriptorPool(self.ctx.device, self.pool, 0)
            self._sets.clear()
            self.ctx.epoch += 1
        layouts = [self.set_layout]
        dsai = vk.VkDescriptorSetAllocateInfo(descriptorPool=self.pool, descriptorSetCount=1, pSetLayouts=layouts)
        ds = vk.vkAllocateDescriptorSets(self.ctx.device, dsai)[0]
        infos = [vk.VkDescriptorBufferInfo(buffer=b.handle, offset=0, range=b.nbytes) for b in buffers]
        writes = [vk.VkWriteDescriptorSet(dstSet=ds, dstBinding=i, descriptorCount=1,
                                          descriptorType=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, pBufferInfo=[infos[i]])
                  for i in range(len(buffers))]
        if writes:
            vk.vkUpdateDescriptorSets(self.ctx.device, len(writes), writes, 0, None)
        del infos, writes
        self._sets[key] = ds
        return ds

    def destroy(self) -> None:
        vk, dev = self.ctx.vk, self.ctx.device
        vk.vkDestroyDescriptorPool(dev, self.pool, None)
        vk.vkDestroyPipeline(dev, self.handle, None)
        vk.vkDestroyShaderModule(dev, self.module, None)
        vk.vkDestroyPipelineLayout(dev, self.layout, None)
        vk.vkDestroyDescriptorSetLayout(dev, self.set_layout, None)


def _load_spirv(name: str) -> bytes:
    path = resources.files(__package__.rsplit(".", 2)[0]).joinpath("shaders", f"{name}.spv")
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise VulkanUnavailable(f"compiled shader {path} is missing; run scripts/build_shaders.py "
                                "(needs glslc: `apt-get install glslc`)") from None


def get_pipeline(ctx: VulkanContext, kernel: Kernel) -> Pipeline:
    """The compute pipeline of a kernels.Kernel (its SPIR-V, bindings and push layout), created once per context."""
    with ctx.lock:
        p = ctx._pipelines.get(kernel)
        if p is None:
            p = ctx._pipelines[kernel] = Pipeline(ctx, kernel, _load_spirv(kernel.name))
        return p


def staging(ctx: VulkanContext, nbytes: int, direction: str) -> Buffer:
    """The context's staging buffer for ``direction`` ('up' or 'down'), grown to at least ``nbytes`` and kept."""
    b = ctx._staging.get(direction)
    if b is None or b.nbytes < nbytes:
        if b is not None:
            b.destroy()
        size = 1 << max(16, (int(nbytes) - 1).bit_length())
        b = ctx._staging[direction] = Buffer.staging(ctx, size, cached=direction == "down")
    return b


def scratch(ctx: VulkanContext, nbytes: int, name: str = "scratch") -> Buffer:
    """A pooled storage buffer of at least ``nbytes`` (sizes rounded up to a power of two); ``close()`` gives it
    back to the context's pool and the next request of that size class reuses its memory."""
    size = 1 << max(8, (max(1, int(nbytes)) - 1).bit_length())
    free = ctx._scratch.get(size)
    if free:
        b = free.pop()
        b.name = name
        return b
    return Buffer(ctx, size, name, pooled=True)


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


def _submit(ctx: VulkanContext, cmd):
    """Submit ``cmd`` and return its fence (from the context's pool) without waiting."""
    vk = ctx.vk
    with ctx.lock:
        fence = ctx._free_fences.pop() if ctx._free_fences else vk.vkCreateFence(ctx.device, vk.VkFenceCreateInfo(), None)
        cmds = [cmd]
        si = vk.VkSubmitInfo(commandBufferCount=1, pCommandBuffers=cmds)
        sis = [si]
        try:
            vk.vkQueueSubmit(ctx.queue, 1, sis, fence)
        except BaseException:
            ctx._free_fences.append(fence)
            raise
        ctx.stats.submits += 1
        return fence


def _wait(ctx: VulkanContext, fence) -> None:
    """Wait for a fence from _submit and give it back to the context."""
    vk = ctx.vk
    fences = [fence]
    try:
        vk.vkWaitForFences(ctx.device, 1, fences, vk.VK_TRUE, _NO_TIMEOUT)
    finally:
        vk.vkResetFences(ctx.device, 1, fences)
        with ctx.lock:
            ctx._free_fences.append(fence)


def _submit_and_wait(ctx: VulkanContext, cmd) -> None:
    _wait(ctx, _submit(ctx, cmd))


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
        self.epoch = ctx.epoch
        self.buffers: dict[int, Buffer] = {}  # every buffer the recording uses (a Program checks they live)
        self.cmd = _take_command_buffer(ctx)
        flags = 0 if reusable else vk.VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT
        cbbi = vk.VkCommandBufferBeginInfo(flags=flags)
        vk.vkBeginCommandBuffer(self.cmd, cbbi)
        self.labels: list[str] = []
        self.timings_ms: dict[str, float] = {}
        self.query_pool = None
        self._barrier()
        if timestamps and ctx.timestamps_supported:
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

    def _use(self, *buffers: Buffer) -> None:
        for b in buffers:
            self.buffers[b.serial] = b

    def dispatch(self, kernel: Kernel, buffers: Sequence[Buffer], group_count: tuple[int, int] | int,
                 **push) -> None:
        """Run ``kernel`` over ``group_count`` workgroups with ``buffers`` bound in its table order; ``push`` names
        every push-constant field of the kernel (kernels.py)."""
        vk = self.vk
        gx, gy = (group_count, 1) if isinstance(group_count, int) else group_count
        if gx == 0 or gy == 0:
            return
        pipeline = get_pipeline(self.ctx, kernel)
        data = kernel.pack(push)
        vk.vkCmdBindPipeline(self.cmd, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.handle)
        sets = [pipeline.descriptor_set(buffers)]
        self._use(*buffers)
        vk.vkCmdBindDescriptorSets(self.cmd, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.layout, 0, 1, sets, 0, None)
        if data:
            raw = vk.ffi.new("char[]", data)
            vk.vkCmdPushConstants(self.cmd, pipeline.layout, vk.VK_SHADER_STAGE_COMPUTE_BIT, 0, len(data), raw)
            del raw
        vk.vkCmdDispatch(self.cmd, gx, gy, 1)
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

    def submit(self) -> dict[str, float]:
        vk, ctx = self.vk, self.ctx
        vk.vkEndCommandBuffer(self.cmd)
        try:
            _submit_and_wait(ctx, self.cmd)
            self.timings_ms = _read_stamps(ctx, self.query_pool, self.labels)
        finally:
            self._give_back()
        return self.timings_ms

    def program(self) -> "Program":
        """End the recording and keep it: Program.run() submits it again and again."""
        self.vk.vkEndCommandBuffer(self.cmd)
        prog = Program(self.ctx, self.cmd, self.query_pool, list(self.labels), list(self.buffers.values()), self.epoch)
        self.cmd = self.query_pool = None
        return prog

    def _give_back(self) -> None:
        ctx = self.ctx
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

    It stays valid while every buffer it uses lives and the context's descriptor sets were not reset
    (``valid``); its owner re-records when not. ``close()`` returns its command buffer to the context.
    """

    def __init__(self, ctx: VulkanContext, cmd, query_pool, labels: list[str], buffers: list[Buffer],
                 epoch: int) -> None:
        self.ctx, self.cmd, self.query_pool, self.labels = ctx, cmd, query_pool, labels
        self.buffers, self.epoch = buffers, epoch

    @property
    def valid(self) -> bool:
        return (self.cmd is not None and self.ctx.device is not None and self.epoch == self.ctx.epoch
                and all(b.handle is not None for b in self.buffers))

    def run(self) -> dict[str, float]:
        self.start()
        return self.wait()

    def start(self) -> None:
        """Submit without waiting (the queue runs submissions in order, each opening with a full barrier, so a
        program started next sees this one's writes); ``wait()`` before reading what it wrote."""
        if not self.valid:
            raise RuntimeError("recorded program is stale (a buffer it uses was freed); record it again")
        if getattr(self, "_fence", None) is not None:
            raise RuntimeError("program started twice without a wait")
        self._fence = _submit(self.ctx, self.cmd)

    def wait(self) -> dict[str, float]:
        """Wait for the submission from start(); returns its GPU timings per stage."""
        fence, self._fence = getattr(self, "_fence", None), None
        if fence is None:
            raise RuntimeError("program waited on without a start")
        _wait(self.ctx, fence)
        return _read_stamps(self.ctx, self.query_pool, self.labels)

    @property
    def running(self) -> bool:
        return getattr(self, "_fence", None) is not None

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
