"""The kernel table: for every compute shader, its storage buffers (binding i = the i-th name), its push
constants as a typed layout, and its workgroup size. Every dispatch goes through it (Recorder.dispatch takes a
Kernel and the push values by name), and tests/test_kernels.py reads each SPIR-V's decorations and fails when
the table and the shader disagree, so a binding or push-constant change in GLSL cannot silently misalign.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

# Push-constant field types: std430 scalars, 4 bytes each, packed in order.
_FORMAT = {"uint": "I", "int": "i", "float": "f"}


@dataclass(frozen=True)
class Kernel:
    name: str  # gs_ibl_addon/shaders/<name>.spv
    buffers: tuple[str, ...]  # storage-buffer block names, binding 0, 1, ... of set 0
    push: tuple[tuple[str, str], ...] = ()  # (field, uint | int | float) in declaration order
    local_size: tuple[int, int, int] = (1, 1, 1)

    @property
    def push_size(self) -> int:
        return 4 * len(self.push)

    @property
    def group_size(self) -> int:
        """Invocations per workgroup (for covering n items with groups())."""
        x, y, z = self.local_size
        return x * y * z

    def pack(self, values: dict) -> bytes:
        """The push-constant bytes for ``values`` (exactly the table's field names)."""
        names = [f for f, _ in self.push]
        if set(values) != set(names):
            missing, extra = sorted(set(names) - set(values)), sorted(set(values) - set(names))
            raise TypeError(f"kernel {self.name}: push constants {names}; missing {missing}, unknown {extra}")
        fmt = "<" + "".join(_FORMAT[t] for _, t in self.push)
        return struct.pack(fmt, *(values[f] for f in names))


def _k(name: str, buffers: str, push: str = "", local: tuple[int, ...] = (256,)) -> Kernel:
    fields = tuple((f.split(":")[0], f.split(":")[1] if ":" in f else "uint") for f in push.split())
    return Kernel(name, tuple(buffers.split()), fields, tuple(local) + (1,) * (3 - len(local)))


_SORT_PUSH = "n_blocks shift count_index drop drop_key"
_EMIT = ("Views DepthKey DepthVal Offsets Total InstKey InstVal Count Prepared Rects Owners",
         "n capacity n_views n_tiles")
_RASTER = ("Views Ranges InstVal Prepared Image Depth Count",
           "n_views total_tiles chunks total_pixels write_depth plane_forms", (16, 16))
_RASTER_CUT = (_RASTER[0] + " Cut Behind",) + _RASTER[1:]
KERNELS: dict[str, Kernel] = {k.name: k for k in (
    # renderer (render/renderer.py)
    _k("gs_preprocess", "PosOp Scale Rot SH Views Prepared TileCount DepthKey DepthVal Rects Origin Lod Live",
       "n dilation_angle:float near:float sh_k n_views energy_preserving lod lod_tau:float lod_cell:float "
       "lod_ox:float lod_oy:float lod_oz:float srgb sort_order sh_splat_major compact"),
    _k("gs_lod_compact", "DepthKey Live SortKey SortVal", "n"),
    _k("gs_gather_counts", "DepthKey DepthVal TileCount Offsets Count", "n count_index"),
    _k("gs_emit_owners", "Offsets Total Owners", "n capacity"),
    _k("gs_emit", *_EMIT),
    _k("gs_emit_per_splat", *_EMIT),  # the same gs_emit.glsl, one thread per splat (Owners unread)
    _k("gs_ranges", "InstKey Count Ranges"),
    _k("gs_raster", *_RASTER),
    _k("gs_raster_conic", *_RASTER),  # the same gs_raster.glsl with the conic pre-test
    _k("gs_raster_strips", *_RASTER),  # ... with strip masks
    _k("gs_raster_conic_strips", *_RASTER),  # ... with both
    _k("gs_merge", "Partial Image PartialDepth Depth", "chunks total_pixels write_depth"),
    # camera frames with a depth cut (FRONT in Image, BEHIND in Behind): each raster above with RASTER_CUT
    _k("gs_raster_cut", *_RASTER_CUT),
    _k("gs_raster_conic_cut", *_RASTER_CUT),
    _k("gs_raster_strips_cut", *_RASTER_CUT),
    _k("gs_raster_conic_strips_cut", *_RASTER_CUT),
    _k("gs_merge_cut", "Partial Image PartialDepth Depth PartialBehind Behind", "chunks total_pixels write_depth"),
    # prefix sums and radix sorts (render/gpu_sort.py)
    _k("scan_block", "Data Sums", "n"),
    _k("scan_add", "Data Sums", "n"),
    _k("radix_hist", "Keys Hist Count", _SORT_PUSH),
    _k("radix_scatter", "KeysIn ValsIn KeysOut ValsOut Hist Count", _SORT_PUSH),
    _k("radix8_hist", "Keys Hist Count", _SORT_PUSH + " block_rounds", (128,)),
    _k("radix8_scatter", "KeysIn ValsIn KeysOut ValsOut Hist Count", _SORT_PUSH + " block_rounds scanned coalesce",
       (256,)),
    # probe filters (probe/gpu_filters.py)
    _k("probe_split_alpha", "Frame Omega Cube Partial", "n n_groups"),
    _k("probe_fill_holes", "Frame Fill", "n per_probe"),
    _k("probe_sh_project", "Cube Omega Partial", "n n_groups"),
    _k("probe_sh_irradiance", "Coeffs Out", "m clamp_negative", (64,)),
    _k("probe_convolve", "Cube Out", "n m phi_steps theta_steps", (64,)),
    _k("probe_downsample", "Src Omega Dst", "n", (64,)),
    _k("probe_faces_to_size", "Src Omega Dst", "n m src_at dst_at", (64,)),  # probe/gpu_assemble.py
    _k("probe_face_parts", "A B Out", "n", (64,)),  # probe/gpu_assemble.py
    _k("probe_cube_read", "Cube Out", "n m", (64,)),
    _k("probe_integrate", "Cube Texels Out", "n m", (128,)),
    _k("probe_ggx", "Mips Samples Lods Levels Out", "n n_mips n_levels total", (64,)),
    _k("probe_latlong", "Cube Out", "n width height", (64,)),
    # the light volume's maps from a frame with depth (probe/gpu_volume_maps.py)
    _k("volume_maps_prep", "Frame Depth Omega IrrIn VisIn",
       "n f g far:float near:float covered:float hole_r:float hole_g:float hole_b:float", (64,)),
    _k("volume_maps_apply", "Matrix In Out", "n_in rows probes channels stride at extra", (64,)),
)}


def kernel(name: str) -> Kernel:
    try:
        return KERNELS[name]
    except KeyError:
        raise KeyError(f"no kernel {name!r} in core/vk/kernels.py (known: {', '.join(sorted(KERNELS))})") from None
