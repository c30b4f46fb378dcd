"""The bake's settings vocabulary, in one place: the irradiance methods (their names on the command line and in
ProbeSettings, the filter each runs, their labels and descriptions in Blender) and the face-size limits. The core
(bake, probe.filters), the command line and the Blender panel all import it, so a method is added or renamed here
and nowhere else.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class IrradianceMethod:
    name: str  # ProbeSettings.method and --method value
    filter: str  # probe.filters.filter_probe's method
    label: str  # Blender's enum name
    description: str  # Blender's tooltip and the command line's help


IRRADIANCE_METHODS: tuple[IrradianceMethod, ...] = (
    IrradianceMethod("auto", "exact", "Auto",
                     "Exact integral; with Face Size 0 the faces grow until the irradiance meets the tolerance"),
    IrradianceMethod("sh", "sh", "Spherical Harmonics",
                     "9 SH coefficients (fast, smooth; rings next to small bright lights)"),
    IrradianceMethod("conv", "convolve", "Cosine Convolution",
                     "Sampled cosine-weighted integral per irradiance texel (the thesis's method; noisy)"),
    IrradianceMethod("box", "box", "Box Filter", "Box-filtered mip chain (fast approximation)"),
    IrradianceMethod("exact", "exact", "Exact",
                     "Integral over every radiance texel with its exact solid angle (GPU; the most accurate)"),
)
METHOD_NAMES: tuple[str, ...] = tuple(m.name for m in IRRADIANCE_METHODS)
FILTER_METHODS: tuple[str, ...] = ("sh", "convolve", "box", "exact")  # what filter_probe runs
# ProbeSettings.method -> filter_probe's method ("convolve" is accepted as the filter's own name too)
METHOD_ALIASES: dict[str, str] = {**{m.name: m.filter for m in IRRADIANCE_METHODS}, "convolve": "convolve"}

DEFAULT_METHOD = "auto"
DEFAULT_IRRADIANCE_SIZE = 16  # irradiance cube face size (lat-long output is 4x as wide)
DEFAULT_TOLERANCE = 0.01  # relative RMS irradiance error the settings are chosen for (core/tolerance.py)
MIN_TOLERANCE = 0.001  # below 0.1% the render's own error floor (0.005-0.02% on the synthetic scenes) is near
MAX_TOLERANCE = 0.5
# Help texts here are plain text (the command line escapes them for argparse).
TOLERANCE_HELP = (f"relative RMS irradiance error allowed (default 0.01 = 1%, {MIN_TOLERANCE:g}-{MAX_TOLERANCE:g}): "
                  "face size, irradiance size and level of detail are chosen from an error estimate to meet it "
                  "(docs/accuracy.md)")
IRRADIANCE_SIZES = (8, 16, 32)  # what irradiance size 0 chooses from, by the error of reading between texels
DEFAULT_DOWNSAMPLE_TO = 32  # exact method: integrate a <= 32^2-face copy (rel RMS loss ~2e-4, docs/accuracy.md)
AUTO_FIRST_FACE = 32  # the face-size search renders this and twice this, then jumps where the estimate says
AUTO_MAX_FACE = 1024  # ... up to here
MAX_FACE_SIZE = 2048  # the largest face size the panel offers
MAX_IRRADIANCE_SIZE = 512  # irradiance is smooth: 16-64 is plenty; beyond this only the filter's cost grows


# Level of detail (render/lod.py): "off" renders every splat; "auto" renders merged splats where a probe's pixel
# allows, each node once its octree cell spans at most LOD_K pixels. Off by default: on the H200 run of
# 2026-12-02 (docs/benchmarks.md) the irradiance error stayed under 0.5% on the random bench scenes at every k
# tried, but not on the guitar capture (3.4% at 32^2, k = 0.5) nor the sample room (0.9% at 32^2, k = 1).
LOD_MODES: tuple[str, ...] = ("off", "auto")
DEFAULT_LOD = "off"
DEFAULT_LOD_K = 1.0
LOD_HELP = ("level of detail: off (every splat) or auto (merged splats where the probe's pixels allow; faster on "
            "millions of splats, irradiance within ~1-3% on small probes, see docs/benchmarks.md)")

# Holes (directions that meet no splat) get light by a stated rule before filtering (core/probe/holes.py): the
# mean of the covered directions by default; "environment" is the caller's radiance (Blender: the World).
HOLE_FILLS: tuple[str, ...] = ("mean", "constant", "environment", "black")
DEFAULT_HOLE_FILL = "mean"
HOLE_FILL_HELP = ("light for directions that meet no splat: mean (of the directions that do, default), constant "
                  "(--hole-colour), black (none)")


# The colour rule (core/colour.py): what a splat's SH + 0.5 means. One vocabulary for the command line's
# --colour-space, probe.json, the splat object's property in Blender and its panel row.
COLOUR_SPACE_ITEMS: tuple[tuple[str, str, str], ...] = (
    ("srgb", "sRGB (trained on photos)",
     "SH + 0.5 is an sRGB-encoded colour, decoded to linear light (as Blender 5.3 reads splats): 3DGS captures"),
    ("linear", "Linear",
     "SH + 0.5 is scene-linear radiance: HDR-trained captures and gs-ibl's synthetic scenes and sample"),
)
COLOUR_SPACE_CHOICES: tuple[str, ...] = tuple(i[0] for i in COLOUR_SPACE_ITEMS) + ("auto",)
DEFAULT_COLOUR_SPACE_CHOICE = "auto"  # the command line: what the file declares, else srgb
COLOUR_SPACE_HELP = ("what the splats' colours mean: srgb (trained on photos: decoded as Blender 5.3 does), linear "
                     "(HDR-trained or synthetic), auto (what the file declares, else srgb; default)")


def blender_colour_space_items() -> list[tuple[str, str, str]]:
    """EnumProperty items of the splat object's colour space: identifier (the name in capitals), label, tip."""
    return [(name.upper(), label, tip) for name, label, tip in COLOUR_SPACE_ITEMS]


def method_help() -> str:
    """One line per method for the command line's --help."""
    return "; ".join(f"{m.name}: {m.description}" for m in IRRADIANCE_METHODS)


def blender_method_items() -> list[tuple[str, str, str]]:
    """EnumProperty items: identifier (the name in capitals), label, description."""
    return [(m.name.upper(), m.label, m.description) for m in IRRADIANCE_METHODS]


def method_from_blender(identifier: str) -> str:
    """The ProbeSettings method of a Blender enum identifier."""
    name = identifier.lower()
    if name not in METHOD_NAMES:
        raise ValueError(f"unknown irradiance method {identifier!r}: use one of {', '.join(METHOD_NAMES)}")
    return name
