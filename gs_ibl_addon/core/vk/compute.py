"""Storage buffers, compute pipelines and a command recorder.

The `vulkan` package's trap (shared/NOTES-vulkan-and-gpu.md): cffi frees a temporary struct as soon as Python drops
it, so a nested create-info written inline can hand the driver freed memory. Here every nested struct, array and
string is bound to a local name that lives until the call returns; nowhere else builds create-infos.
"""
from __future__ import annotations

import itertools
import struct
from typing import Sequence

import numpy as np

from .context import VulkanContext

_serial = itertools.count(1)


class Buffer:
    """A storage buffer. Device-local where the device has such memory; mapped directly when it is host-visible."""

    def __init__(self, ctx: VulkanContext, nbytes: int, name: str = "") -> None:
        vk = ctx.vk
        self.ctx, self.name, self.serial = ctx, name, next(_serial)
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
        if self._map is not None:
            self._map[offset:offset + raw.nbytes] = raw
            return
        staging = Buffer._staging(self.ctx, raw.nbytes)
        staging._map[:raw.nbytes] = raw
        with Recorder(self.ctx) as rec:
            rec.copy(staging, self, raw.nbytes, dst_offset=offset)
        staging.destroy()

    def read(self, dtype=np.uint8, count: int | None = None, offset: int = 0) -> np.ndarray:
        dt = np.dtype(dtype)
        n = (self.nbytes - offset) // dt.itemsize if count is None else int(count)
        nbytes = n * dt.itemsize
        if self._map is not None and self.host_cached:
            return np.frombuffer(self._map, dtype=dt, count=n, offset=offset).copy()
        staging = Buffer._staging(self.ctx, nbytes, cached=True)
        with Recorder(self.ctx) as rec:
            rec.copy(self, staging, nbytes, src_offset=offset)
        out = np.frombuffer(staging._map, dtype=dt, count=n).copy()
        staging.destroy()
        return out

    @staticmethod
    def _staging(ctx: VulkanContext, nbytes: int, cached: bool = False) -> "Buffer":
        b = Buffer.__new__(Buffer)
        vk = ctx.vk
        b.ctx, b.name, b.serial, b.nbytes = ctx, "staging", next(_serial), max(int(nbytes), 16)
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

    def __del__(self) -> None:
        try:
            self.destroy()
        except Exception:
            pass


class Pipeline:
    """A compute pipeline whose set 0 is ``n_buffers`` storage buffers, plus a push-constant block."""

    POOL_SETS = 512

    def __init__(self, ctx: VulkanContext, name: str, spirv: bytes, n_buffers: int, push_size: int) -> None:
        vk = ctx.vk
        self.ctx, self.name, self.n_buffers, self.push_size = ctx, name, n_buffers, push_size
        bindings = [vk.VkDescriptorSetLayoutBinding(binding=i, descriptorType=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                                                    descriptorCount=1, stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT)
                    for i in range(n_buffers)]
        dslci = vk.VkDescriptorSetLayoutCreateInfo(bindingCount=len(bindings), pBindings=bindings)
        self.set_layout = vk.vkCreateDescriptorSetLayout(ctx.device, dslci, None)
        set_layouts = [self.set_layout]
        ranges = [vk.VkPushConstantRange(stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT, offset=0, size=push_size)] if push_size else []
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
                                              descriptorCount=max(1, n_buffers) * self.POOL_SETS)]
        dpci = vk.VkDescriptorPoolCreateInfo(maxSets=self.POOL_SETS, poolSizeCount=1, pPoolSizes=pool_sizes)
        self.pool = vk.vkCreateDescriptorPool(ctx.device, dpci, None)
        self._sets: dict[tuple, object] = {}

    def descriptor_set(self, buffers: Sequence[Buffer]):
        vk = self.ctx.vk
        if len(buffers) != self.n_buffers:
            raise ValueError(f"pipeline {self.name} takes {self.n_buffers} buffers, got {len(buffers)}")
        key = tuple(b.serial for b in buffers)
        ds = self._sets.get(key)
        if ds is not None:
            return ds
        if len(self._sets) >= self.POOL_SETS:
            # Safe: every submission waits for completion, so no set is in flight here.
            vk.vkResetDescriptorPool(self.ctx.device, self.pool, 0)
            self._sets.clear()
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


def groups(n_items: int, group_size: int, ctx: VulkanContext) -> tuple[int, int]:
    """Workgroup counts (x, y) covering ``n_items``; shaders linearise with gl_WorkGroupID.y * gl_NumWorkGroups.x."""
    g = max(1, -(-int(n_items) // group_size))
    mx = min(ctx.max_workgroups[0], 65535)
    if g <= mx:
        return g, 1
    return mx, -(-g // mx)


class Recorder:
    """Records dispatches into one command buffer; ``with Recorder(ctx) as r:`` submits and waits on exit.

    A full compute barrier follows every dispatch/copy/fill, so consecutive stages see each other's writes.
    ``timestamp(label)`` marks the end of a stage; ``timings_ms`` holds stage durations after submission.
    """

    MAX_STAMPS = 64

    def __init__(self, ctx: VulkanContext, timestamps: bool = False) -> None:
        vk = self.vk = ctx.vk
        self.ctx = ctx
        cbai = vk.VkCommandBufferAllocateInfo(commandPool=ctx.command_pool, level=vk.VK_COMMAND_BUFFER_LEVEL_PRIMARY,
                                              commandBufferCount=1)
        self.cmd = vk.vkAllocateCommandBuffers(ctx.device, cbai)[0]
        cbbi = vk.VkCommandBufferBeginInfo(flags=vk.VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT)
        vk.vkBeginCommandBuffer(self.cmd, cbbi)
        self.labels: list[str] = []
        self.timings_ms: dict[str, float] = {}
        self.query_pool = None
        if timestamps and ctx.timestamps_supported:
            qpci = vk.VkQueryPoolCreateInfo(queryType=vk.VK_QUERY_TYPE_TIMESTAMP, queryCount=self.MAX_STAMPS)
            self.query_pool = vk.vkCreateQueryPool(ctx.device, qpci, None)
            vk.vkCmdResetQueryPool(self.cmd, self.query_pool, 0, self.MAX_STAMPS)
            self.timestamp("start")

    def _barrier(self) -> None:
        vk = self.vk
        access = (vk.VK_ACCESS_SHADER_READ_BIT | vk.VK_ACCESS_SHADER_WRITE_BIT | vk.VK_ACCESS_TRANSFER_READ_BIT
                  | vk.VK_ACCESS_TRANSFER_WRITE_BIT)
        mb = vk.VkMemoryBarrier(srcAccessMask=access, dstAccessMask=access)
        mbs = [mb]
        stages = vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | vk.VK_PIPELINE_STAGE_TRANSFER_BIT
        vk.vkCmdPipelineBarrier(self.cmd, stages, stages, 0, 1, mbs, 0, None, 0, None)

    def dispatch(self, pipeline: Pipeline, buffers: Sequence[Buffer], group_count: tuple[int, int] | int,
                 push: bytes = b"") -> None:
        vk = self.vk
        gx, gy = (group_count, 1) if isinstance(group_count, int) else group_count
        if gx == 0 or gy == 0:
            return
        vk.vkCmdBindPipeline(self.cmd, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.handle)
        sets = [pipeline.descriptor_set(buffers)]
        vk.vkCmdBindDescriptorSets(self.cmd, vk.VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.layout, 0, 1, sets, 0, None)
        if pipeline.push_size:
            data = bytes(push).ljust(pipeline.push_size, b"\0")
            if len(data) != pipeline.push_size:
                raise ValueError(f"{pipeline.name}: push constants are {len(data)} bytes, expected {pipeline.push_size}")
            raw = vk.ffi.new("char[]", data)
            vk.vkCmdPushConstants(self.cmd, pipeline.layout, vk.VK_SHADER_STAGE_COMPUTE_BIT, 0, len(data), raw)
            del raw
        vk.vkCmdDispatch(self.cmd, gx, gy, 1)
        self._barrier()

    def fill(self, buffer: Buffer, value: int = 0, nbytes: int | None = None) -> None:
        size = buffer.nbytes if nbytes is None else (int(nbytes) + 3) // 4 * 4
        self.vk.vkCmdFillBuffer(self.cmd, buffer.handle, 0, size, value & 0xFFFFFFFF)
        self._barrier()

    def copy(self, src: Buffer, dst: Buffer, nbytes: int, src_offset: int = 0, dst_offset: int = 0) -> None:
        vk = self.vk
        regions = [vk.VkBufferCopy(srcOffset=src_offset, dstOffset=dst_offset, size=nbytes)]
        vk.vkCmdCopyBuffer(self.cmd, src.handle, dst.handle, 1, regions)
        self._barrier()

    def timestamp(self, label: str) -> None:
        if self.query_pool is None or len(self.labels) >= self.MAX_STAMPS:
            return
        self.vk.vkCmdWriteTimestamp(self.cmd, self.vk.VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                                    self.query_pool, len(self.labels))
        self.labels.append(label)

    def submit(self) -> dict[str, float]:
        vk, ctx = self.vk, self.ctx
        vk.vkEndCommandBuffer(self.cmd)
        cmds = [self.cmd]
        si = vk.VkSubmitInfo(commandBufferCount=1, pCommandBuffers=cmds)
        sis = [si]
        fci = vk.VkFenceCreateInfo()
        fence = vk.vkCreateFence(ctx.device, fci, None)
        try:
            with ctx.lock:
                vk.vkQueueSubmit(ctx.queue, 1, sis, fence)
            vk.vkWaitForFences(ctx.device, 1, [fence], vk.VK_TRUE, 0xFFFFFFFFFFFFFFFF)
        finally:
            vk.vkDestroyFence(ctx.device, fence, None)
            vk.vkFreeCommandBuffers(ctx.device, ctx.command_pool, 1, cmds)
        if self.query_pool is not None:
            n = len(self.labels)
            data = vk.ffi.new("uint64_t[]", n)
            vk.vkGetQueryPoolResults(ctx.device, self.query_pool, 0, n, n * 8, data, 8,
                                     vk.VK_QUERY_RESULT_64_BIT | vk.VK_QUERY_RESULT_WAIT_BIT)
            ticks = np.frombuffer(vk.ffi.buffer(data, n * 8), np.uint64).astype(np.float64)
            ms = ticks * ctx.timestamp_period_ns * 1e-6
            for i in range(1, n):
                self.timings_ms[self.labels[i]] = self.timings_ms.get(self.labels[i], 0.0) + float(ms[i] - ms[i - 1])
            self.timings_ms["total"] = float(ms[-1] - ms[0]) if n > 1 else 0.0
            vk.vkDestroyQueryPool(ctx.device, self.query_pool, None)
            self.query_pool = None
        return self.timings_ms

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.submit()
        else:
            self.vk.vkEndCommandBuffer(self.cmd)
            self.vk.vkFreeCommandBuffers(self.ctx.device, self.ctx.command_pool, 1, [self.cmd])
            if self.query_pool is not None:
                self.vk.vkDestroyQueryPool(self.ctx.device, self.query_pool, None)


def pack(fmt: str, *values) -> bytes:
    """Push-constant bytes (std430 scalars: I = uint, i = int, f = float)."""
    return struct.pack("<" + fmt, *values)
