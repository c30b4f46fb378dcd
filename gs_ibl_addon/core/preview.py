"""A picture a person can look at after a bake: radiance, irradiance and a lit sphere, side by side (PNG).

Drawn with numpy and written with OpenImageIO (already loaded for the EXRs, labels from its built-in font):
matplotlib took 1-2 s just to import, more than the rest of the picture.
"""
from __future__ import annotations

import os

import numpy as np

from .probe import ProbeResult, cube_to_latlong, sample_cube_bilinear

PANEL_HEIGHT = 256  # lat-long panels are 512 x 256: the 13-inch figure they replace showed them at about that size
_GAP, _LABEL, _TITLE_LINE = 12, 22, 20
_MAGENTA = (1.0, 0.0, 1.0)
# zlib level of the PNG: 1 wrote the sample room's preview in a third of the default's (6) time for a file
# about a fifth larger (2026-12-05, lavapipe machine)
PNG_LEVEL = 1


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


def outline(mask: np.ndarray) -> np.ndarray:
    """The pixels of ``mask`` that touch a pixel outside it (4-neighbours; the lat-long wraps left to right)."""
    edge = np.zeros_like(mask)
    edge[1:] |= mask[1:] & ~mask[:-1]
    edge[:-1] |= mask[:-1] & ~mask[1:]
    edge |= mask & ~np.roll(mask, 1, 1)
    edge |= mask & ~np.roll(mask, -1, 1)
    return edge


def preview_panels(result: ProbeResult) -> tuple[list[tuple[np.ndarray, str]], float]:
    """The three display-referred (sRGB, 0-1) panels with their labels, and the exposure used for all of them."""
    rad = np.asarray(result.radiance)
    rad_ll = cube_to_latlong(rad, 2 * PANEL_HEIGHT)
    irr_ll = cube_to_latlong(result.irradiance[..., :3], 2 * PANEL_HEIGHT)
    sphere = lit_sphere(result.irradiance, PANEL_HEIGHT)
    # one exposure for all panels, from the irradiance (what lights meshes), so they compare by eye
    exposure = float(-np.log2(max(np.percentile(irr_ll, 99), 1e-6)))
    rad_img = _tonemap(rad_ll[..., :3], exposure)
    label = "radiance (lat-long, Blender mapping)"
    if rad.shape[-1] == 4 and result.hole_fraction > 0:
        rad_img[outline(rad_ll[..., 3] < 0.5)] = _MAGENTA
        fill = (result.hole_fill or {}).get("method", "black")
        label += f"; magenta: holes ({'left black' if fill == 'black' else f'filled, {fill}'})"
    return [(rad_img, label), (_tonemap(irr_ll, exposure), "irradiance E/pi (lat-long)"),
            (_tonemap(sphere, exposure), "white diffuse sphere")], exposure


def write_preview(result: ProbeResult, path: str | os.PathLike, title: str = "") -> None:
    """Three panels: radiance lat-long (holes outlined in magenta), irradiance lat-long, a white diffuse sphere,
    under a title naming the scene and the bake's settings."""
    from .image_io import ImageIOError, _oiio
    oiio = _oiio()
    path = os.fspath(path)
    panels, _ = preview_panels(result)
    s = result.settings
    face = np.asarray(result.radiance).shape[1]
    sub = (f"{result.splat_count:,} splats - {face}^2 faces - method {s.get('method')} - "
           f"holes {100 * result.hole_fraction:.1f}% - {result.device}")
    lines = ([title] if title else []) + [sub]
    top = _GAP + _TITLE_LINE * len(lines) + _GAP // 2
    width = sum(img.shape[1] for img, _ in panels) + _GAP * (len(panels) + 1)
    canvas = np.ones((top + _LABEL + PANEL_HEIGHT + _GAP, width, 3), np.float32)
    x = _GAP
    for img, _ in panels:
        canvas[top + _LABEL:top + _LABEL + img.shape[0], x:x + img.shape[1]] = img
        x += img.shape[1] + _GAP
    buf = oiio.ImageBuf(oiio.ImageSpec(width, canvas.shape[0], 3, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(0, width, 0, canvas.shape[0], 0, 1, 0, 3), canvas)
    black = (0.0, 0.0, 0.0)
    for k, line in enumerate(lines):
        oiio.ImageBufAlgo.render_text(buf, width // 2, _GAP + _TITLE_LINE * (k + 1) - 5, line, 15, "", black,
                                      alignx="center")
    x = _GAP
    for img, label in panels:
        oiio.ImageBufAlgo.render_text(buf, x, top + _LABEL - 6, label, 13, "", black)
        x += img.shape[1] + _GAP
    pixels = np.round(np.clip(buf.get_pixels(oiio.FLOAT), 0, 1) * 255).astype(np.uint8)
    out = oiio.ImageOutput.create(path)
    spec = oiio.ImageSpec(width, canvas.shape[0], 3, oiio.UINT8)
    spec.attribute("png:compressionLevel", PNG_LEVEL)
    if out is None or not out.open(path, spec):
        raise ImageIOError(f"{path}: cannot write the preview PNG ({oiio.geterror()})")
    try:
        if not out.write_image(pixels):
            raise ImageIOError(f"{path}: writing the preview's pixels failed ({out.geterror()})")
    finally:
        out.close()
