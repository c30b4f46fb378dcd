"""A picture a person can look at after a bake: radiance, irradiance and a lit sphere, side by side (PNG)."""
from __future__ import annotations

import os

import numpy as np

from .probe import ProbeResult, cube_to_latlong, sample_cube_bilinear


def lit_sphere(irradiance_cube: np.ndarray, size: int = 256, albedo: float = 0.8) -> np.ndarray:
    """(size, size, 3) image of a diffuse sphere seen from -Y (Blender's front view) lit by the irradiance map,
    over a dark grey background. Outgoing radiance of a Lambertian surface = albedo * E/pi."""
    c = (np.arange(size) + 0.5) / size * 2 - 1
    zz, xx = np.meshgrid(-c, c, indexing="ij")  # image rows go down in z
    r2 = xx * xx + zz * zz
    inside = r2 < 1
    ny = -np.sqrt(np.clip(1 - r2, 0, 1))  # facing the viewer at -Y
    normals = np.stack([xx, ny, zz], -1)
    img = np.full((size, size, 3), 0.02)
    img[inside] = albedo * sample_cube_bilinear(irradiance_cube[..., :3], normals[inside])
    return img


def _tonemap(x: np.ndarray, exposure: float) -> np.ndarray:
    from .colour import linear_to_srgb
    return np.clip(linear_to_srgb(np.clip(x * 2.0 ** exposure, 0, 1)), 0, 1)


def write_preview(result: ProbeResult, path: str | os.PathLike, title: str = "") -> None:
    """Three panels: radiance lat-long (with holes hatched), irradiance lat-long, a white diffuse sphere."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rad = np.asarray(result.radiance)
    face = rad.shape[1]
    rad_ll = cube_to_latlong(rad, 1024)  # a display image: 1024 columns show a 13-inch figure in full
    irr_ll = cube_to_latlong(result.irradiance[..., :3], 256)
    sphere = lit_sphere(result.irradiance)
    # one exposure for all panels, from the irradiance (what lights meshes), so they compare by eye
    exposure = float(-np.log2(max(np.percentile(irr_ll, 99), 1e-6)))
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), gridspec_kw={"width_ratios": [2, 2, 1]})
    panels = [(rad_ll[..., :3], "radiance (lat-long, Blender mapping)"),
              (irr_ll, "irradiance E/\u03c0 (lat-long)"), (sphere, "white diffuse sphere")]
    for ax, (img, label) in zip(axes, panels):
        ax.imshow(_tonemap(img, exposure), interpolation="nearest")
        ax.set_title(label, fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
    if rad.shape[-1] == 4 and result.hole_fraction > 0:
        holes = rad_ll[..., 3] < 0.5
        axes[0].contour(holes, levels=[0.5], colors="magenta", linewidths=0.8)
        fill = (result.hole_fill or {}).get("method", "black")
        how = "left black" if fill == "black" else f"filled ({fill})"
        axes[0].set_title(f"radiance (lat-long, Blender mapping)\nmagenta outline: holes, no splat seen; {how}",
                          fontsize=9)
    s = result.settings
    sub = (f"{result.splat_count:,} splats \u00b7 {face}\u00b2 faces \u00b7 method {s.get('method')} \u00b7 "
           f"holes {100 * result.hole_fraction:.1f}% \u00b7 {result.device}")
    fig.suptitle((title + "\n" if title else "") + sub, fontsize=10)
    fig.tight_layout()
    fig.savefig(os.fspath(path), dpi=100)
    plt.close(fig)
