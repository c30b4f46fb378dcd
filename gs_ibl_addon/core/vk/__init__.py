"""A small Vulkan compute layer: one context, storage buffers, compute pipelines, a command recorder with timestamps.

Every pipeline in gs-ibl uses the same shape: set 0 holds only storage buffers (binding i = the i-th buffer passed
to a dispatch) and parameters travel as push constants (at most 128 bytes, the guaranteed minimum).
"""
from .context import VulkanContext, VulkanUnavailable, get_context
from .compute import Buffer, Recorder

__all__ = ["VulkanContext", "VulkanUnavailable", "get_context", "Buffer", "Recorder"]
