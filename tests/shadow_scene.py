"""The shadows' test scene (issue 36, item 3), shared by tests/test_shadows_blender.py and benchmarks/shadow_bench.py.

A flat splat floor (dense small flat splats at z = 0, storage order shuffled), a splat sky dome whose colours are an
analytic sun-like sky (synthetic.BrightPatch: a gradient plus a 7-degree disc about 80 times brighter), a sphere
0.1 above the floor, a camera looking down at it. The probe's light is the same sky as a lat-long in our World
(lighting/world.py, as a bake writes it), so that our shadows and Cycles light from the same environment.

The measurement: ours is the splat floor's F12 colour with Shadows on Splats over the same with it off (the ratio
the splats were multiplied by); Cycles' is a diffuse mesh plane of the splats' colour in place of the splat floor,
path traced in the same World with the sphere over the same without it (4 bounces: the light the grey sphere
reflects into its own shadow is in it, as ours adds it from the sphere's material colour). D = 1 - ratio on floor
pixels the sphere does not cover.
"""
from __future__ import annotations

import math

import numpy as np

from gs_ibl_addon.core import cubemap, synthetic

FLOOR_RGB = (0.5, 0.45, 0.4)
SPHERE_AT, SPHERE_R = (0.0, 0.0, 0.5), 0.4
SUN = synthetic.BrightPatch(direction=(0.55, 0.2, 0.81))
CAM_AT, CAM_LOOK = (0.3, -3.0, 2.2), (-0.2, 0.0, 0.2)


def sky_latlong(height: int = 128) -> np.ndarray:
    return SUN(cubemap.latlong_directions(2 * height, height)).astype(np.float32)


def floor_splats(half: float = 2.5, spacing: float = 0.04, seed: int = 3):
    g = np.arange(-half, half + 1e-9, spacing)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    c = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1)
    s = synthetic._disks(c, np.tile([0.0, 0.0, 1.0], (len(c), 1)), np.tile(FLOOR_RGB, (len(c), 1)), spacing, 0.1,
                         0.99)
    return s.subset(np.random.default_rng(seed).permutation(s.count))


def sky_splats(n: int = 6000, radius: float = 9.0):
    s = synthetic.shell_scene(SUN, n, radius=radius)
    return s.subset(np.nonzero(s.positions[:, 2] > -0.2)[0])


def _look_at(bpy, ob, at, target):
    from mathutils import Vector
    ob.location = at
    ob.rotation_euler = (Vector(target) - Vector(at)).to_track_quat("-Z", "Y").to_euler()


def _diffuse(bpy, name, rgb):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (*rgb, 1.0)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(d.outputs[0], out.inputs["Surface"])
    return mat


def build(bpy, width: int, height: int, samples: int = 16, bounces: int = 4, sky_n: int = 6000,
          sphere_albedo: float = 0.5):
    """The scene in the current (empty) file: splat floor and sky, sphere, camera, our World; Cycles on the CPU."""
    from gs_ibl_addon.blender.lighting import world as gw
    from gs_ibl_addon.blender.splats.object import create_splat_object
    scene = bpy.context.scene
    floor = create_splat_object(bpy.context, floor_splats(), "Floor")
    sky = create_splat_object(bpy.context, sky_splats(sky_n), "Sky")
    for ob in (floor, sky):
        ob.hide_render = False
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=SPHERE_R, location=SPHERE_AT)
    sphere = bpy.context.active_object
    sphere.name = "Sphere"
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_diffuse(bpy, "Grey", (sphere_albedo,) * 3))
    cd = bpy.data.cameras.new("Cam")
    cd.lens, cd.sensor_width = 40.0, 36.0
    cam = bpy.data.objects.new("Cam", cd)
    scene.collection.objects.link(cam)
    _look_at(bpy, cam, CAM_AT, CAM_LOOK)
    scene.camera = cam
    image = gw.latlong_image("radiance", sky_latlong(), name="Shadow Sky")
    scene.world = gw.build_world(image)
    r = scene.render
    r.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = bounces
    scene.cycles.diffuse_bounces = bounces
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.color_mode = "RGBA"
    scene.view_settings.view_transform = "Standard"
    bpy.context.view_layer.update()
    return {"scene": scene, "floor": floor, "sky": sky, "sphere": sphere}


def render(bpy, path) -> np.ndarray:
    """F12 to ``path`` (EXR), read back rows top first."""
    scene = bpy.context.scene
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(str(path))
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    out = px.reshape(img.size[1], img.size[0], 4)[::-1].copy()
    bpy.data.images.remove(img)
    return out


def ours(bpy, parts, tmp) -> tuple[np.ndarray, np.ndarray, dict]:
    """(the F12 frame with Shadows on Splats, without it, the first one's record: timings, messages)."""
    from gs_ibl_addon.blender.render import frame
    scene = parts["scene"]
    rs = scene.gs_ibl_render
    rs.enabled, rs.shadows = True, True
    on = render(bpy, tmp / "ours_on.exr")
    record = dict(next(iter(frame.last_render(scene)["frames"].values())))
    record["messages"] = list(frame.last_render(scene)["messages"])
    rs.shadows = False
    off = render(bpy, tmp / "ours_off.exr")
    rs.shadows = True
    return on, off, record


def sphere_mask(bpy, parts, tmp) -> np.ndarray:
    """Pixels the sphere covers at all (its render's alpha), grown by one pixel."""
    scene = parts["scene"]
    scene.gs_ibl_render.enabled = False
    keep = scene.cycles.samples, scene.render.film_transparent
    scene.cycles.samples, scene.render.film_transparent = 1, True
    parts["floor"].hide_render = parts["sky"].hide_render = True
    try:
        a = render(bpy, tmp / "sphere_alpha.exr")[..., 3] > 1e-3
    finally:
        scene.cycles.samples, scene.render.film_transparent = keep
        parts["floor"].hide_render = parts["sky"].hide_render = False
        scene.gs_ibl_render.enabled = True
    grown = a.copy()
    grown[1:] |= a[:-1]
    grown[:-1] |= a[1:]
    grown[:, 1:] |= a[:, :-1]
    grown[:, :-1] |= a[:, 1:]
    return grown


def cycles(bpy, parts, tmp, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Cycles' frames (H, W, 4) with the sphere and without it: a diffuse plane of the floor's colour in place of
    the splats, splats off."""
    scene = parts["scene"]
    scene.gs_ibl_render.enabled = False
    scene.render.film_transparent = True
    parts["floor"].hide_render = parts["sky"].hide_render = True
    bpy.ops.mesh.primitive_plane_add(size=5.0, location=(0.0, 0.0, 0.0))
    plane = bpy.context.active_object
    plane.data.materials.append(_diffuse(bpy, "Floor", FLOOR_RGB))
    keep = scene.cycles.samples
    scene.cycles.samples = samples
    try:
        with_sphere = render(bpy, tmp / "cycles_with.exr")
        parts["sphere"].hide_render = True
        without = render(bpy, tmp / "cycles_without.exr")
    finally:
        parts["sphere"].hide_render = False
        bpy.data.objects.remove(plane)
        parts["floor"].hide_render = parts["sky"].hide_render = False
        scene.cycles.samples = keep
        scene.gs_ibl_render.enabled = True
    return with_sphere, without


LUMA = np.array([0.2126, 0.7152, 0.0722])


def box(a: np.ndarray, mask: np.ndarray, r: int) -> np.ndarray:
    """Mean of ``a`` over the (2r + 1)^2 pixels round each pixel, counting only ``mask``'s."""
    if r <= 0:
        return np.where(mask, a, 0.0)
    k = 2 * r + 1
    p = np.pad(np.where(mask, a, 0.0), r)
    m = np.pad(mask.astype(float), r)
    h, w = a.shape
    s = sum(p[i:i + h, j:j + w] for i in range(k) for j in range(k))
    n = sum(m[i:i + h, j:j + w] for i in range(k) for j in range(k))
    return s / np.maximum(n, 1)


def compare(on, off, with_sphere, without, sphere: np.ndarray, blur: int = 1, strong: float = 0.2) -> dict:
    """Darkening D = 1 - (with shadow / without) of the luminance on the floor pixels (both frames opaque there,
    the sphere not on them), ours against Cycles. Cycles' noise does not choose the pixels and is not divided
    before it is averaged: the shadowed region is where ours darkens by more than 0.05 (grown by 2 pixels, so a
    shadow Cycles draws wider is counted), a region's D is 1 - sum(with) / sum(without), and per pixel both frames
    are box filtered ((2 blur + 1)^2) before the division. Also the whole floor's darkening (no region chosen)."""
    floor = ~sphere & (off[..., 3] > 0.99) & (without[..., 3] > 0.99)
    y = {k: np.asarray(v)[..., :3] @ LUMA for k, v in (("on", on), ("off", off), ("with", with_sphere),
                                                         ("without", without))}
    d_o = 1.0 - box(y["on"], floor, blur) / np.maximum(box(y["off"], floor, blur), 1e-9)
    d_c = 1.0 - box(y["with"], floor, blur) / np.maximum(box(y["without"], floor, blur), 1e-9)
    core = floor & (d_o > 0.05)
    region = core.copy()
    for _ in range(2):
        region[1:] |= region[:-1]
        region[:-1] |= region[1:]
        region[:, 1:] |= region[:, :-1]
        region[:, :-1] |= region[:, 1:]
    region &= floor

    def dark(a, b, m):
        return float(1.0 - y[a][m].sum() / y[b][m].sum())
    d_ours, d_cyc = dark("on", "off", region), dark("with", "without", region)
    s = floor & (d_o > strong)
    rel = np.abs(d_o - d_c)[s] / np.maximum(d_c[s], 1e-9)
    return {"pixels": int(region.sum()), "d_ours": d_ours, "d_cycles": d_cyc,
            "rel": abs(d_ours - d_cyc) / d_cyc,
            "floor_d_ours": dark("on", "off", floor), "floor_d_cycles": dark("with", "without", floor),
            "strong_pixels": int(s.sum()),
            "pixel_rel_median": float(np.median(rel)) if len(rel) else math.nan,
            "pixel_rel_p90": float(np.percentile(rel, 90)) if len(rel) else math.nan,
            "D_ours": np.where(floor, d_o, np.nan), "D_cycles": np.where(floor, d_c, np.nan), "region": region}
