"""What the World chain of blender/render/compositor.py gives in this Blender, per engine, without splats (docs/final-
frame.md section 10): our nodes
installed (Film Transparent turned on by us), BEHIND a constant premultiplied colour c, FRONT empty. Expected where
no splats: R + (1 - a_R)(c + (1 - a_c) W) with R the transparent render, W the World
with c = 0 it is Blender's own
render with Film Transparent off. Also: does the Environment pass hold (1 - a_R) W at mesh edges?

    PYTHON world_pass_probe.py -- REPO WORKDIR CYCLES EEVEE     (PYTHON: a bpy module's Python, e.g.
    /var/cache/gs-ibl/bpy42/bin/python
    bpy 5.3: scripts/blender_roots.sh chroot trixie /opt/bpy53/bin/python
    /tmp/…/world_pass_probe.py -- /src /tmp/… CYCLES EEVEE). Prints one line "PROBE-WORLD {json}"."""
import json
import os
import sys

import numpy as np
repo = sys.argv[sys.argv.index("--") + 1]
work = sys.argv[sys.argv.index("--") + 2]
engines = sys.argv[sys.argv.index("--") + 3:]
sys.path.insert(0, repo)
import bpy
from gs_ibl_addon.blender.render import compositor
W = (0.15, 0.3, 0.5)
bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene
w = bpy.data.worlds.new("Sky")
if w.node_tree is None:
    w.use_nodes = True
w.node_tree.nodes["Background"].inputs["Color"].default_value = (*W, 1.0)
sc.world = w
cd = bpy.data.cameras.new("C")
cam = bpy.data.objects.new("C", cd)
sc.collection.objects.link(cam)
sc.camera = cam
cam.location = (0, -5, 0)
cam.rotation_euler = (1.5708, 0, 0)
me = bpy.data.meshes.new("P")
me.from_pydata([(-0.9, 0, -0.6), (0.7, 0, -0.7), (0.5, 0, 0.8), (-0.8, 0, 0.6)], [], [(0, 1, 2, 3)])
mat = bpy.data.materials.new("E")
if mat.node_tree is None:
    mat.use_nodes = True
nt = mat.node_tree
nt.nodes.clear()
em = nt.nodes.new("ShaderNodeEmission")
em.inputs["Color"].default_value = (0.9, 0.6, 0.1, 1)
out = nt.nodes.new("ShaderNodeOutputMaterial")
nt.links.new(em.outputs[0], out.inputs["Surface"])
me.materials.append(mat)
ob = bpy.data.objects.new("P", me)
sc.collection.objects.link(ob)
r = sc.render
r.resolution_x, r.resolution_y = 48, 36
r.image_settings.file_format = "OPEN_EXR"
r.image_settings.color_mode = "RGBA"
r.image_settings.color_depth = "32"
sc.view_settings.view_transform = "Standard"
sc.cycles.samples, sc.cycles.device, sc.cycles.use_denoising = 8, "CPU", False
sc.eevee.taa_render_samples = 8


def shot(name):
    r.filepath = os.path.join(work, name + ".exr")
    bpy.ops.render.render(write_still=True)
    im = bpy.data.images.load(r.filepath)
    px = np.empty(len(im.pixels), np.float32)
    im.pixels.foreach_get(px)
    bpy.data.images.remove(im)
    return px.reshape(36, 48, 4)


res = {"blender": bpy.app.version_string}
for eng in engines:
    if eng == "EEVEE":
        for n in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE"):
            try:
                r.engine = n
                break
            except TypeError:
                continue
    else:
        r.engine = eng
    r.film_transparent = False
    opaque = shot(f"opaque_{eng}")
    r.film_transparent = True
    transp = shot(f"transparent_{eng}")
    r.film_transparent = False
    compositor.install(sc)
    assert compositor.shows_world(sc) and r.film_transparent
    res[eng + "_chained"] = not compositor.world_pass_empty(sc)  # 4.2 EEVEE: left out (the pass is black)
    ours0 = shot(f"ours_empty_{eng}")
    c = np.array([0.1, 0.05, 0.2, 0.4], np.float32)
    behind = compositor.find_image(sc, sc.view_layers[0].name, compositor.BEHIND_ROLE)
    behind.pixels.foreach_set(np.tile(c, 48 * 36))
    behind.update()
    ours = shot(f"ours_behind_{eng}")
    compositor.remove(sc)
    assert not r.film_transparent and not sc.view_layers[0].use_pass_environment
    a = transp[..., 3:4]
    want = transp + (1 - a) * (c + (1 - c[3]) * np.array([*W, 1.0], np.float32))
    edge = (a[..., 0] > 0.02) & (a[..., 0] < 0.98)
    naive = transp + (1 - a) * (opaque - transp)  # the Environment pass laid under as it is: the World twice weighted
    res[eng] = {"engine": r.engine, "edge_px": int(edge.sum()),
                "no_splats_vs_blender_opaque_max": float(np.abs(ours0 - opaque).max()),
                "behind_vs_expected_max": float(np.abs(ours - want).max()),
                "behind_vs_expected_edges_max": float(np.abs(ours - want)[edge].max()),
                "env_pass_laid_under_as_is_edges_max": float(np.abs(naive - opaque)[edge].max()),
                "alpha_min": float(ours[..., 3].min())}
print("PROBE-WORLD " + json.dumps(res))
