"""What the driver compiled each kernel into (VK_KHR_pipeline_executable_properties): registers, shared memory,
spills, as the driver names them, so that a kernel's occupancy can be read off instead of guessed.

  python benchmarks/shader_stats.py [--kernels gs_raster,gs_raster_conic] [--spv gs_raster:variant.spv,...]
         [--trials out/trials] [--csv out/bench/shader_stats.csv]

Makes its own device with the extension and its feature on (the renderer's context asks for neither), builds each
kernel of core/vk/kernels.py from the extension's SPIR-V with statistics captured, and prints one row per kernel and
statistic. On NVIDIA the occupancy of a 256-lane kernel follows from the register count (65,536 a multiprocessor,
allocated per warp in units of 256: warps = 65536 / (32 * ceil(regs * 32 / 256) * 256 / 32)) and the shared memory.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from bench_common import trial_dirs  # noqa: E402
from gs_ibl_addon.core.vk.kernels import KERNELS  # noqa: E402
from gs_ibl_addon.core.vk.pipelines import _load_spirv  # noqa: E402

EXT = "VK_KHR_pipeline_executable_properties"


def _text(vk, value) -> str:
    return value if isinstance(value, str) else vk.ffi.string(value).decode()


def _device(vk, want: str | None):
    app = vk.VkApplicationInfo(pApplicationName="gs-ibl shader_stats", apiVersion=vk.VK_MAKE_VERSION(1, 2, 0))
    ici = vk.VkInstanceCreateInfo(pApplicationInfo=app)
    instance = vk.vkCreateInstance(ici, None)
    phys = vk.vkEnumeratePhysicalDevices(instance)
    names = [_text(vk, vk.vkGetPhysicalDeviceProperties(p).deviceName) for p in phys]
    pick = next((i for i, n in enumerate(names) if want and want.lower() in n.lower()), None)
    if pick is None:  # a discrete GPU first, as the renderer's context does
        types = [vk.vkGetPhysicalDeviceProperties(p).deviceType for p in phys]
        pick = types.index(2) if 2 in types else 0
    pd = phys[pick]
    exts = {e.extensionName for e in vk.vkEnumerateDeviceExtensionProperties(pd, None)}
    if EXT not in exts:
        raise SystemExit(f"{names[pick]} does not offer {EXT}")
    families = vk.vkGetPhysicalDeviceQueueFamilyProperties(pd)
    family = next(i for i, f in enumerate(families) if f.queueFlags & vk.VK_QUEUE_COMPUTE_BIT)
    priorities = vk.ffi.new("float[]", [1.0])
    qci = vk.VkDeviceQueueCreateInfo(queueFamilyIndex=family, queueCount=1, pQueuePriorities=priorities)
    qcis = [qci]
    feature = vk.VkPhysicalDevicePipelineExecutablePropertiesFeaturesKHR(pipelineExecutableInfo=vk.VK_TRUE)
    ext_names = [EXT]
    dci = vk.VkDeviceCreateInfo(pNext=feature, queueCreateInfoCount=1, pQueueCreateInfos=qcis,
                                enabledExtensionCount=1, ppEnabledExtensionNames=ext_names)
    device = vk.vkCreateDevice(pd, dci, None)
    del qci, qcis, feature, ext_names, dci, priorities
    return instance, device, names[pick]


def kernel_stats(vk, device, name: str, spv: str | None = None) -> list[tuple[str, str, str]]:
    """(executable, statistic, value) rows of kernel ``name`` as this device compiles it (``spv``: another build of
    it, with the same bindings and push constants)."""
    k = KERNELS[name]
    bindings = [vk.VkDescriptorSetLayoutBinding(binding=i, descriptorType=vk.VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                                                descriptorCount=1, stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT)
                for i in range(len(k.buffers))]
    dslci = vk.VkDescriptorSetLayoutCreateInfo(bindingCount=len(bindings), pBindings=bindings)
    set_layout = vk.vkCreateDescriptorSetLayout(device, dslci, None)
    set_layouts = [set_layout]
    ranges = ([vk.VkPushConstantRange(stageFlags=vk.VK_SHADER_STAGE_COMPUTE_BIT, offset=0, size=k.push_size)]
              if k.push_size else [])
    plci = vk.VkPipelineLayoutCreateInfo(setLayoutCount=1, pSetLayouts=set_layouts,
                                         pushConstantRangeCount=len(ranges), pPushConstantRanges=ranges or None)
    layout = vk.vkCreatePipelineLayout(device, plci, None)
    code = bytes(_load_spirv(name)) if spv is None else open(spv, "rb").read()
    smci = vk.VkShaderModuleCreateInfo(codeSize=len(code), pCode=code)
    module = vk.vkCreateShaderModule(device, smci, None)
    entry = "main"
    stage = vk.VkPipelineShaderStageCreateInfo(stage=vk.VK_SHADER_STAGE_COMPUTE_BIT, module=module, pName=entry)
    cpci = vk.VkComputePipelineCreateInfo(flags=vk.VK_PIPELINE_CREATE_CAPTURE_STATISTICS_BIT_KHR, stage=stage,
                                          layout=layout)
    cpcis = [cpci]
    pipeline = vk.vkCreateComputePipelines(device, None, 1, cpcis, None)[0]
    get_props = vk.vkGetDeviceProcAddr(device, "vkGetPipelineExecutablePropertiesKHR")
    get_stats = vk.vkGetDeviceProcAddr(device, "vkGetPipelineExecutableStatisticsKHR")
    info = vk.VkPipelineInfoKHR(pipeline=pipeline)
    rows = []
    for i, prop in enumerate(list(get_props(device, info))):
        exe = _text(vk, prop.name)
        ei = vk.VkPipelineExecutableInfoKHR(pipeline=pipeline, executableIndex=i)
        for st in get_stats(device, ei):
            fmt = st.format
            v = st.value
            value = {vk.VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_BOOL32_KHR: lambda: bool(v.b32),
                     vk.VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_INT64_KHR: lambda: v.i64,
                     vk.VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_UINT64_KHR: lambda: v.u64,
                     vk.VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_FLOAT64_KHR: lambda: v.f64}[fmt]()
            rows.append((exe, _text(vk, st.name), str(value)))
    vk.vkDestroyPipeline(device, pipeline, None)
    vk.vkDestroyShaderModule(device, module, None)
    vk.vkDestroyPipelineLayout(device, layout, None)
    vk.vkDestroyDescriptorSetLayout(device, set_layout, None)
    del code, stage, cpci, cpcis, entry, bindings, set_layouts, ranges
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kernels", default="gs_raster,gs_raster_conic,radix8_scatter,gs_emit,gs_preprocess")
    ap.add_argument("--spv", default="", help="KERNEL:PATH,...: other builds of a kernel, as rows of their own")
    ap.add_argument("--trials", help="a folder of trial builds (benchmarks/kernel_trials.py build): each of their "
                    "kernels named in --kernels as a row of its own, labelled KERNEL:TRIAL")
    ap.add_argument("--device", default=os.environ.get("GS_IBL_DEVICE"))
    ap.add_argument("--csv")
    args = ap.parse_args()
    import vulkan as vk
    instance, device, dev_name = _device(vk, args.device)
    out = []
    builds = [(name, None, name) for name in args.kernels.split(",") if name]
    for x in args.spv.split(","):
        if x:
            name, spv = x.split(":", 1)
            builds.append((name, spv, f"{name}:{os.path.basename(spv)}"))
    kernels = set(args.kernels.split(","))
    for folder in trial_dirs(args.trials):
        for f in sorted(os.listdir(folder)):
            if f.endswith(".spv") and f[:-4] in kernels:  # beside the committed build's row
                builds.append((f[:-4], os.path.join(folder, f), f"{f[:-4]}:{os.path.basename(folder)}"))
    for name, spv, label in builds:
        for exe, stat, value in kernel_stats(vk, device, name, spv):
            out.append({"device": dev_name, "kernel": label, "executable": exe, "statistic": stat, "value": value})
    vk.vkDestroyDevice(device, None)
    vk.vkDestroyInstance(instance, None)
    width = max(len(r["statistic"]) for r in out) if out else 10
    for r in out:
        print(f"{r['kernel']:40s} {r['statistic']:{width}s} {r['value']}")
    if args.csv:
        os.makedirs(os.path.dirname(os.path.abspath(args.csv)), exist_ok=True)
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(out[0]))
            w.writeheader()
            w.writerows(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
