"""A small Vulkan compute layer: a context, storage buffers, compute pipelines, a recorder, recorded programs.

  context.py    the device and what lives as long as it: queue, pools of frame resources (command buffers,
                fences, query pools, staging and scratch buffers), transfer counts (``ctx.stats``)
  kernels.py    the kernel table: every shader's storage buffers, typed push constants and workgroup size
  constants.py  the numbers Python and GLSL share (written into shaders/constants.glsl)
  compute.py    Buffer, Pipeline, Recorder (one-shot submissions) and Program (a recording submitted again)

Every pipeline has the same shape: set 0 holds only storage buffers (binding i = the kernel's i-th buffer) and
parameters travel as push constants (at most 128 bytes, the guaranteed minimum).
"""
from .context import VulkanContext, VulkanUnavailable, get_context
from .compute import Buffer, Program, Recorder, scratch
from .kernels import KERNELS, Kernel

__all__ = ["VulkanContext", "VulkanUnavailable", "get_context", "Buffer", "Program", "Recorder", "scratch",
           "KERNELS", "Kernel"]
