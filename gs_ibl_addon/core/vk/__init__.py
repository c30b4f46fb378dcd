"""A small Vulkan compute layer: a context, storage buffers, compute pipelines, a recorder, recorded programs.

  context.py    the device and what lives as long as it: queue, pools of frame resources (command buffers,
                fences, query pools, staging and scratch buffers), transfer counts (``ctx.stats``)
  kernels.py    the kernel table: every shader's storage buffers, typed push constants and workgroup size
  constants.py  the numbers Python and GLSL share (written into shaders/constants.glsl)
  buffers.py    Buffer (with-scoped), host transfers through the kept staging buffers, pooled scratch buffers,
                buffers kept by key between bakes (kept)
  pipelines.py  one compute pipeline per kernel and context, descriptor sets cached by buffer
  commands.py   Recorder (one-shot submissions), Program (a recording submitted again), groups()

Every pipeline has the same shape: set 0 holds only storage buffers (binding i = the kernel's i-th buffer) and
parameters travel as push constants (at most 128 bytes, the guaranteed minimum).
"""
from .context import VulkanContext, VulkanUnavailable, get_context
from .buffers import Buffer, kept, scratch
from .commands import Program, Recorder, groups
from .kernels import KERNELS, Kernel

__all__ = ["VulkanContext", "VulkanUnavailable", "get_context", "Buffer", "kept", "Program", "Recorder", "groups",
           "scratch", "KERNELS", "Kernel"]
