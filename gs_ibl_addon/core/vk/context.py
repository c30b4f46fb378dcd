"""Vulkan instance/device selection and the objects that live as long as the device.

Device choice: ``GS_IBL_DEVICE`` (or the ``device`` argument) may be an index, a case-insensitive substring of the
device name, ``gpu`` (discrete or integrated GPU only) or ``cpu`` (lavapipe). By default a discrete GPU is taken,
else an integrated or virtual GPU, else any device (lavapipe).
"""
from __future__ import annotations

import os
import sys
import threading

from .pipeline_cache import PipelineCache


def _install_hint(platform: str = sys.platform) -> str:
    if platform == "darwin":
        return ("macOS has no Vulkan of its own: install MoltenVK with the Vulkan loader (the LunarG Vulkan SDK for "
                "macOS with its system-global installation, so that /usr/local/lib/libvulkan.dylib exists, or "
                "`brew install molten-vk vulkan-loader`), then restart Blender")
    if platform.startswith("win"):
        return "update your GPU driver: NVIDIA, AMD and Intel drivers install the Vulkan loader (vulkan-1.dll)"
    return ("install a Vulkan loader and driver: on Debian/Ubuntu `apt-get install libvulkan1 mesa-vulkan-drivers` "
            "(Mesa lavapipe runs Vulkan on the CPU), or your GPU driver's Vulkan package")


INSTALL_HINT = _install_hint()


class VulkanUnavailable(RuntimeError):
    """No Vulkan loader, no device, or the requested device is missing."""


def _vk():
    try:
        import vulkan
        return vulkan
    except (ImportError, OSError) as e:  # the cffi module raises OSError when libvulkan.so.1 is missing
        raise VulkanUnavailable(f"Vulkan is not available ({e}); {INSTALL_HINT}") from e


_TYPE_RANK = {2: 0, 1: 1, 3: 2, 4: 3, 0: 4}  # discrete, integrated, virtual, cpu, other


class VulkanContext:
    """Instance, one device with one compute queue, a command pool, and caches of pipelines and descriptor sets."""

    def __init__(self, device: str | None = None) -> None:
        vk = self.vk = _vk()
        app = vk.VkApplicationInfo(pApplicationName="gs-ibl", applicationVersion=1, pEngineName="gs-ibl",
                                   engineVersion=1, apiVersion=vk.VK_MAKE_VERSION(1, 2, 0))
        # MoltenVK (macOS) is a portability driver: loaders >= 1.3.216 list it only when asked to.
        portability = "VK_KHR_portability_enumeration" in self._instance_extensions()
        extensions = ["VK_KHR_portability_enumeration"] if portability else []
        flags = vk.VK_INSTANCE_CREATE_ENUMERATE_PORTABILITY_BIT_KHR if portability else 0
        ici = vk.VkInstanceCreateInfo(pApplicationInfo=app, flags=flags, enabledExtensionCount=len(extensions),
                                      ppEnabledExtensionNames=extensions or None)
        try:
            self.instance = vk.vkCreateInstance(ici, None)
        except Exception as e:
            raise VulkanUnavailable(f"could not create a Vulkan instance ({type(e).__name__}); {INSTALL_HINT}") from e
        phys = vk.vkEnumeratePhysicalDevices(self.instance)
        if not phys:
            raise VulkanUnavailable(f"the Vulkan loader found no device; {INSTALL_HINT}")
        self.physical_device = self._choose(phys, device if device is not None else os.environ.get("GS_IBL_DEVICE"))
        props = vk.vkGetPhysicalDeviceProperties(self.physical_device)
        name = props.deviceName
        self.device_name: str = name if isinstance(name, str) else vk.ffi.string(name).decode()
        self.device_type: int = props.deviceType
        self.is_cpu = props.deviceType == vk.VK_PHYSICAL_DEVICE_TYPE_CPU
        self.timestamp_period_ns: float = props.limits.timestampPeriod
        self.max_workgroups = tuple(props.limits.maxComputeWorkGroupCount)
        self.max_storage_range: int = int(props.limits.maxStorageBufferRange)  # one binding's bytes
        self.memory_properties = vk.vkGetPhysicalDeviceMemoryProperties(self.physical_device)
        self.subgroup_size, self.subgroup_ballot = self._subgroup_info()

        families = vk.vkGetPhysicalDeviceQueueFamilyProperties(self.physical_device)
        self.queue_family = next(i for i, f in enumerate(families) if f.queueFlags & vk.VK_QUEUE_COMPUTE_BIT)
        self.timestamps_supported = families[self.queue_family].timestampValidBits > 0 and self.timestamp_period_ns > 0
        priorities = vk.ffi.new("float[]", [1.0])
        qci = vk.VkDeviceQueueCreateInfo(queueFamilyIndex=self.queue_family, queueCount=1, pQueuePriorities=priorities)
        qcis = [qci]
        # a portability device (MoltenVK) must have its subset extension enabled when it offers it
        dev_ext = [e for e in ("VK_KHR_portability_subset",) if e in self._device_extensions()]
        dci = vk.VkDeviceCreateInfo(queueCreateInfoCount=1, pQueueCreateInfos=qcis, enabledExtensionCount=len(dev_ext),
                                    ppEnabledExtensionNames=dev_ext or None)
        self.device = vk.vkCreateDevice(self.physical_device, dci, None)
        self.queue = vk.vkGetDeviceQueue(self.device, self.queue_family, 0)
        pci = vk.VkCommandPoolCreateInfo(queueFamilyIndex=self.queue_family,
                                         flags=vk.VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT)
        self.command_pool = vk.vkCreateCommandPool(self.device, pci, None)
        self.pipeline_cache = PipelineCache(vk, self.physical_device, self.device)  # loaded from disk, saved back
        self._pipelines: dict[object, object] = {}
        self.lock = threading.RLock()
        # Frame resources, made once and reused by every submission: command buffers, fences, timestamp query
        # pools, two staging buffers (host -> GPU, GPU -> host) that grow to the largest transfer and stay, and a
        # pool of scratch buffers by size. buffers.py, pipelines.py and commands.py make and take them; this module
        # only holds them and destroys them with the device.
        self._free_cmds: list = []
        self._free_fences: list = []
        self.queued: list = []  # (command buffer, owner) started and not yet submitted: commands.flush
        self._free_queries: list = []
        self._staging: dict[str, object] = {}
        self._scratch: dict[int, list] = {}
        # Descriptor pools in use: per pool (by id), the recordings and kept programs that bound one of its sets
        # (commands.py counts them). A full pool is retired (pipelines.py) and reset once none uses it
        # (reset_descriptor_pools), so no recording or program ever loses a set it bound.
        self.pool_users: dict[int, int] = {}
        self.pools_retired = False
        # Profiling (benchmarks): every recording gets timestamps, so stats.gpu_ms counts all GPU time.
        self.stamp_all = False
        # Stage objects cached per context (tables uploaded once, recorded programs), closed with it.
        self.cache: dict[object, object] = {}
        self.stats = TransferStats()

    def _instance_extensions(self) -> set[str]:
        try:
            return {e.extensionName for e in self.vk.vkEnumerateInstanceExtensionProperties(None)}
        except Exception:
            return set()

    def _device_extensions(self) -> set[str]:
        try:
            return {e.extensionName for e in self.vk.vkEnumerateDeviceExtensionProperties(self.physical_device, None)}
        except Exception:
            return set()

    def _subgroup_info(self) -> tuple[int, bool]:
        vk = self.vk
        sub = vk.ffi.new("VkPhysicalDeviceSubgroupProperties*")
        sub.sType = vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES
        props2 = vk.ffi.new("VkPhysicalDeviceProperties2*")
        props2.sType = vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2
        props2.pNext = sub
        vk.vkGetPhysicalDeviceProperties2(self.physical_device, props2)
        compute = bool(sub.supportedStages & vk.VK_SHADER_STAGE_COMPUTE_BIT)
        ballot = compute and bool(sub.supportedOperations & vk.VK_SUBGROUP_FEATURE_BALLOT_BIT) and bool(
            sub.supportedOperations & vk.VK_SUBGROUP_FEATURE_BASIC_BIT)
        return int(sub.subgroupSize), ballot

    def _choose(self, phys: list, want: str | None):
        vk = self.vk
        infos = []
        for i, p in enumerate(phys):
            pr = vk.vkGetPhysicalDeviceProperties(p)
            name = pr.deviceName if isinstance(pr.deviceName, str) else vk.ffi.string(pr.deviceName).decode()
            infos.append((i, p, name, pr.deviceType))
        names = ", ".join(f"{i}: {n}" for i, _, n, _ in infos)
        if want:
            w = want.strip().lower()
            if w.isdigit():
                if int(w) < len(infos):
                    return infos[int(w)][1]
            elif w == "gpu":
                gpus = [x for x in infos if x[3] in (1, 2, 3)]
                if gpus:
                    return min(gpus, key=lambda x: _TYPE_RANK[x[3]])[1]
            elif w == "cpu":
                cpus = [x for x in infos if x[3] == 4]
                if cpus:
                    return cpus[0][1]
            else:
                for _, p, n, _ in infos:
                    if w in n.lower():
                        return p
            raise VulkanUnavailable(f"no Vulkan device matches GS_IBL_DEVICE={want!r}; devices here: {names}")
        return min(infos, key=lambda x: _TYPE_RANK.get(x[3], 5))[1]

    def memory_type(self, type_bits: int, flags: int) -> int:
        mp = self.memory_properties
        for i in range(mp.memoryTypeCount):
            if type_bits & (1 << i) and (mp.memoryTypes[i].propertyFlags & flags) == flags:
                return i
        raise VulkanUnavailable(f"{self.device_name}: no memory type with flags {flags:#x}")

    def reset_descriptor_pools(self) -> None:
        """Reset the pipelines' full (retired) descriptor pools that no open recording, submission in flight or kept
        program uses (pool_users); called by each new recording."""
        with self.lock:
            if not self.pools_retired:
                return
            left = 0
            for p in self._pipelines.values():
                left += p.reset_retired(lambda pool: self.pool_users.get(id(pool), 0) == 0)
            self.pools_retired = left > 0

    def release(self, buffer) -> None:
        """Return a scratch buffer to the pool (its contents are kept until reused)."""
        self._scratch.setdefault(buffer.nbytes, []).append(buffer)

    def close(self) -> None:
        vk = self.vk
        if getattr(self, "device", None) is None:
            return
        self.queued.clear()  # started programs never waited for: their owners are closing with the device
        vk.vkDeviceWaitIdle(self.device)
        for obj in list(self.cache.values()):
            close = getattr(obj, "close", None)
            if close is not None:
                close()
        self.cache.clear()
        for b in list(self._staging.values()) + [b for free in self._scratch.values() for b in free]:
            b.destroy()
        self._staging.clear()
        self._scratch.clear()
        for f in self._free_fences:
            vk.vkDestroyFence(self.device, f, None)
        for q in self._free_queries:
            vk.vkDestroyQueryPool(self.device, q, None)
        self._free_fences.clear()
        self._free_queries.clear()
        self._free_cmds.clear()  # freed with the pool
        for p in self._pipelines.values():
            p.destroy()
        self._pipelines.clear()
        self.pipeline_cache.close()
        vk.vkDestroyCommandPool(self.device, self.command_pool, None)
        vk.vkDestroyDevice(self.device, None)
        vk.vkDestroyInstance(self.instance, None)
        self.device = None

    def __enter__(self) -> "VulkanContext":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class TransferStats:
    """Host <-> GPU traffic through a context: tests count it to prove a stage boundary stays on the GPU."""

    def __init__(self) -> None:
        self.uploads = self.upload_bytes = self.readbacks = self.readback_bytes = self.submits = 0
        self.gpu_ms = 0.0  # GPU time of timestamped submissions (first to last stamp); all of them with stamp_all

    def snapshot(self) -> dict[str, float]:
        return dict(vars(self))

    def since(self, before: dict[str, float]) -> dict[str, float]:
        return {k: v - before.get(k, 0) for k, v in vars(self).items()}


_CONTEXTS: dict[str | None, VulkanContext] = {}
_CONTEXT_LOCK = threading.Lock()


def get_context(device: str | None = None) -> VulkanContext:
    """The shared context for a device request (``None``: GS_IBL_DEVICE or the default choice), made on first use.

    Another request gets its own context; none is ever closed under live renderers. Code that needs a context
    for a while takes one explicitly (``SplatRenderer(scene, ctx)``, ``filter_probe(..., vk_context=ctx)``), or
    owns one: ``with VulkanContext(device) as ctx:``.
    """
    with _CONTEXT_LOCK:
        ctx = _CONTEXTS.get(device)
        if ctx is None or ctx.device is None:
            ctx = _CONTEXTS[device] = VulkanContext(device)
        return ctx
