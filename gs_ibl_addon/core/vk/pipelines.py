"""Compute pipelines, one per kernels.Kernel and context, with their descriptor sets cached by buffer."""
from __future__ import annotations

from importlib import resources
from typing import Protocol, Sequence

from .context import VulkanContext, VulkanUnavailable
from .kernels import Kernel


class Buffer(Protocol):
    """What binding and recording need of a buffers.Buffer (named here so this layer does not import that one)."""
    handle: object
    serial: int
    nbytes: int


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
        stage = vk.VkPipelineShaderStageCreateInfo(stage=vk.VK_SHADER_STAGE_COMPUTE_BIT, module=self.module,
                                                   pName=entry)
        cpci = vk.VkComputePipelineCreateInfo(stage=stage, layout=self.layout)
        cpcis = [cpci]
        self.handle = vk.vkCreateComputePipelines(ctx.device, ctx.pipeline_cache.handle, 1, cpcis, None)[0]
        del code, stage, cpci, cpcis, entry
        self._pools: list = []  # [current, ...retired]: a full pool is retired, reset once nothing uses its sets
        self._spare: list = []  # reset pools, reused before a new one is made
        self._pool = self._new_pool()
        self._sets: dict[tuple, object] = {}

    def _new_pool(self):
        if self._spare:
            pool = self._spare.pop()
        else:
            vk = self.ctx.vk
            pool_sizes = [vk.VkDescriptorPoolSize(type=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                                                  descriptorCount=max(1, self.n_buffers) * self.POOL_SETS)]
            dpci = vk.VkDescriptorPoolCreateInfo(maxSets=self.POOL_SETS, poolSizeCount=1, pPoolSizes=pool_sizes)
            pool = vk.vkCreateDescriptorPool(self.ctx.device, dpci, None)
        self._pools.insert(0, pool)
        return pool

    @property
    def retired(self) -> int:
        """Full pools waiting for reset_retired (their sets may still be bound by a recording or a program)."""
        return len(self._pools) - 1

    @property
    def pool(self):
        """The pool the sets descriptor_set returns now come from (a recording counts its users: commands.py)."""
        return self._pool

    def reset_retired(self, unused) -> int:
        """Free the sets of the retired pools for which ``unused(pool)`` (the context's reset_descriptor_pools: no
        recording, submission or kept program binds them); returns how many retired pools are left."""
        vk = self.ctx.vk
        keep = [self._pools[0]]
        for pool in self._pools[1:]:
            if unused(pool):
                vk.vkResetDescriptorPool(self.ctx.device, pool, 0)
                self._spare.append(pool)
            else:
                keep.append(pool)
        self._pools = keep
        return len(keep) - 1

    def descriptor_set(self, buffers: Sequence[Buffer]):
        vk = self.ctx.vk
        if len(buffers) != self.n_buffers:
            raise ValueError(f"kernel {self.name} binds {self.kernel.buffers}, got {len(buffers)} buffers")
        key = tuple(b.serial for b in buffers)
        ds = self._sets.get(key)
        if ds is not None:
            return ds
        if len(self._sets) >= self.POOL_SETS:
            # A full pool is retired, not reset: a recording open now, a submission in flight or a kept program
            # may bind its sets (a reset here freed them under a frame being recorded). The context resets it at
            # a later recording's start once none uses it (commands.Recorder, context.pool_users).
            self._pool = self._new_pool()
            self._sets.clear()
            self.ctx.pools_retired = True
        layouts = [self.set_layout]
        dsai = vk.VkDescriptorSetAllocateInfo(descriptorPool=self._pool, descriptorSetCount=1, pSetLayouts=layouts)
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
        for pool in self._pools + self._spare:
            vk.vkDestroyDescriptorPool(dev, pool, None)
        self._pools, self._spare = [], []
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
            # now rather than at close: shared contexts are never closed, and a crash keeps what was compiled
            ctx.pipeline_cache.save()
        return p
