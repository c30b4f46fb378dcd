"""Probe lighting: radiance cube -> diffuse irradiance (SH, cosine convolution, box) and GGX prefiltered maps.

Every filter has a plain numpy implementation here (the references GPU versions are tested against), and
all of them read directions and solid angles from core.cubemap. Irradiance values are E(n)/pi.
"""
from .box import box_irradiance, downsample_cube, mip_chain
from .convolve import cosine_convolve
from .filters import METHODS, filter_probe
from .ggx import ggx_prefilter
from .latlong import cube_to_latlong, sh_irradiance_latlong
from .reference import analytic_irradiance, cube_from_function, exact_irradiance, exact_irradiance_cube
from .result import ProbeResult, write_probe
from .sampling import sample_cube_bilinear, split_alpha
from .sh_project import project_cube, sh_basis_any, sh_irradiance, sh_irradiance_cube

__all__ = [
    "box_irradiance", "downsample_cube", "mip_chain", "cosine_convolve", "METHODS", "filter_probe", "ggx_prefilter",
    "cube_to_latlong", "sh_irradiance_latlong", "analytic_irradiance", "cube_from_function", "exact_irradiance",
    "exact_irradiance_cube", "ProbeResult", "write_probe", "sample_cube_bilinear", "split_alpha", "project_cube",
    "sh_basis_any", "sh_irradiance", "sh_irradiance_cube",
]
