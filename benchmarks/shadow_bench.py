"""Shadows on Splats against Cycles (issue 36 item 3), and what they cost per frame.

The scene is tests/shadow_scene.py's: a sphere 0.1 above a flat splat floor under a sun-like splat sky (a 7-degree
sun about 80 times brighter than the sky: about 45 % of the floor's light), our World holding the same sky. Ours: the
floor's F12 (bpy 5.0.1 module, Cycles for the meshes) with Shadows on Splats over the same with it off. Cycles: a
diffuse mesh plane of the splats' colour in place of the splat floor, path traced (4 bounces) in that World with
the sphere over without it. Two spheres: grey (albedo 0.5: its reflected light fills its shadow, in Cycles and in
ours) and black (the shadow is the blocked light alone). D = 1 - ratio on floor pixels the sphere does not cover;
the region is where ours darkens by more than 0.05, grown by 2 pixels (tests/shadow_scene.py compare()).

Cost: an F12 at --cost-size with the setting on and off; the frame record's parts (mesh depth, splats drawn and
read back on the Vulkan device, shadows) give the shadows' time against the splats' in the same frame.

    .venv/bin/python benchmarks/shadow_bench.py                      # 320x240 at 256 spp, cost at 1920x1080
    .venv/bin/python benchmarks/shadow_bench.py --size 160x120 --samples 64 --cost-size 480x270 --no-write

Writes docs/bench/shadow_<device>.csv, docs/img/shadow_bench.png (per-pixel D, ours against Cycles),
docs/img/shadow_ours_vs_cycles.png (the frames side by side) and docs/img/shadow_room.png (no measurement: the
bundled sample room baked through the add-on with two lights split off, a grey sphere and a red cube on its floor,
F12 with Shadows on Splats off and on); prints the table for docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import pathlib
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))


def _size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def _tone(rgb: np.ndarray) -> np.ndarray:
    """sRGB-encoded, clipped: for looking at."""
    x = np.clip(rgb, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=_size, default=(320, 240), help="the accuracy frame, WxH")
    ap.add_argument("--samples", type=int, default=256, help="Cycles samples of the reference")
    ap.add_argument("--cost-size", type=_size, default=(1920, 1080), help="the cost frame, WxH")
    ap.add_argument("--device", default="lavapipe", help="the name in the CSV file's name")
    ap.add_argument("--no-write", action="store_true", help="print only")
    ap.add_argument("--no-room", action="store_true", help="skip the sample room's picture")
    args = ap.parse_args()

    import bpy

    import gs_ibl_addon
    import shadow_scene as S
    bpy.ops.wm.read_factory_settings(use_empty=True)
    gs_ibl_addon.register()
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="shadow_bench_"))
    w, h = args.size
    parts = S.build(bpy, w, h, samples=16)
    load0 = os.getloadavg()[0]
    sphere = S.sphere_mask(bpy, parts, tmp)
    rows, frames = [], {}
    colour = parts["sphere"].active_material.node_tree.nodes["Diffuse BSDF"].inputs["Color"]
    for kind, albedo in (("grey", 0.5), ("black", 0.0)):
        colour.default_value = (albedo, albedo, albedo, 1.0)
        ours = S.ours(bpy, parts, tmp)
        t = time.perf_counter()
        with_sphere, without = S.cycles(bpy, parts, tmp, args.samples)
        seconds = time.perf_counter() - t
        frames[kind] = ours[0], with_sphere
        for blur in (0, 1):
            c = S.compare(ours[0], ours[1], with_sphere, without, sphere, blur=blur)
            if kind == "grey" and blur == 1:
                chosen = c
            rows.append({"measure": "accuracy", "reference": kind, "blur": blur, "size": f"{w}x{h}",
                         "samples": args.samples, "region_px": c["pixels"], "d_ours": round(c["d_ours"], 4),
                         "d_cycles": round(c["d_cycles"], 4), "region_rel": round(c["rel"], 4),
                         "floor_d_ours": round(c["floor_d_ours"], 4), "floor_d_cycles": round(c["floor_d_cycles"], 4),
                         "floor_rel": round(abs(c["floor_d_ours"] - c["floor_d_cycles"]) / c["floor_d_cycles"], 4),
                         "pixel_rel_median": round(c["pixel_rel_median"], 4),
                         "pixel_rel_p90": round(c["pixel_rel_p90"], 4), "cycles_s_pair": round(seconds, 1)})
    colour.default_value = (0.5, 0.5, 0.5, 1.0)

    # cost: the whole F12 handler at the cost size, shadows on and off
    cw, ch = args.cost_size
    r = parts["scene"].render
    r.resolution_x, r.resolution_y = cw, ch
    parts["scene"].cycles.samples = 1
    from gs_ibl_addon.blender.render import frame
    cost = {}
    for state in (True, False, True):
        parts["scene"].gs_ibl_render.shadows = state
        S.render(bpy, tmp / "cost.exr")
        rec = next(iter(frame.last_render(parts["scene"])["frames"].values()))
        cost.setdefault(state, []).append(rec)
    best_on = min(cost[True], key=lambda x: x["ms"])
    rows.append({"measure": "cost", "size": f"{cw}x{ch}", "light_samples": best_on.get("light_samples"),
                 "triangles": best_on.get("triangles"), "splats": best_on.get("splats"),
                 "ms_shadows": best_on.get("ms_shadows"), "ms_splats": best_on.get("ms_splats"),
                 "ms_mesh_depth": best_on.get("ms_mesh_depth"), "ms_handler_on": best_on["ms"],
                 "ms_handler_off": cost[False][0]["ms"],
                 "shadows_over_splats": round(best_on["ms_shadows"] / best_on["ms_splats"], 2),
                 "load": round(max(load0, os.getloadavg()[0]), 1)})
    room = None if args.no_room or args.no_write else _room(bpy, S, tmp)
    gs_ibl_addon.unregister()

    date = datetime.date.today().isoformat()
    print(f"\nShadows on Splats against Cycles ({date}, bpy {bpy.app.version_string}, load {rows[-1]['load']} on "
          f"{os.cpu_count()} cores)\n")
    print("| sphere | blur | region px | D ours | D Cycles | region diff | whole floor D ours / Cycles | diff | "
          "per-pixel median / p90 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for x in rows[:-1]:
        print(f"| {x['reference']} | {2 * x['blur'] + 1}x{2 * x['blur'] + 1} | {x['region_px']} | {x['d_ours']:.3f} | "
              f"{x['d_cycles']:.3f} | {100 * x['region_rel']:.1f} % | {x['floor_d_ours']:.4f} / "
              f"{x['floor_d_cycles']:.4f} | {100 * x['floor_rel']:.1f} % | {100 * x['pixel_rel_median']:.1f} / "
              f"{100 * x['pixel_rel_p90']:.1f} % |")
    x = rows[-1]
    print(f"\ncost at {x['size']}: shadows {x['ms_shadows']} ms ({x['light_samples']} light samples, {x['triangles']} "
          f"triangles), splats drawn + read back {x['ms_splats']} ms (x{x['shadows_over_splats']}), mesh depth "
          f"{x['ms_mesh_depth']} ms; the whole handler {x['ms_handler_on']} ms on, {x['ms_handler_off']} ms off")
    if args.no_write:
        return
    out_csv = ROOT / "docs" / "bench" / f"shadow_{args.device}.csv"
    keys = list(dict.fromkeys(k for row in rows for k in row))
    with open(out_csv, "w", newline="") as f:
        wr = csv.DictWriter(f, ["date", *keys])
        wr.writeheader()
        for row in rows:
            wr.writerow({"date": date, **row})
    _plots(chosen, frames["grey"], sphere, ROOT / "docs" / "img")
    if room is not None:
        _room_plot(room, ROOT / "docs" / "img" / "shadow_room.png")
    print(f"wrote {out_csv}, docs/img/shadow_bench.png, docs/img/shadow_ours_vs_cycles.png")


def _room(bpy, S, tmp: pathlib.Path) -> dict:
    """The sample room through the add-on: bake (64^2 faces, two lights split off), F12 off and on, Cycles 32 spp."""
    from gs_ibl_addon.blender.render import frame
    from gs_ibl_addon.blender.splats.object import create_splat_object
    from gs_ibl_addon.core import synthetic
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    room = create_splat_object(bpy.context, synthetic.sample_environment(), "Room")
    room.hide_render = False
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.35, location=(0.3, 0.6, 0.36))
    bpy.ops.object.shade_smooth()
    bpy.context.active_object.data.materials.append(S._diffuse(bpy, "Grey", (0.7, 0.7, 0.7)))
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(-0.6, 1.2, 0.25))
    bpy.context.active_object.data.materials.append(S._diffuse(bpy, "Red", (0.6, 0.1, 0.08)))
    scene.cursor.location = (0.0, 0.0, 1.0)
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    s = bpy.context.active_object.gs_ibl_probe
    s.splats, s.face_size, s.irradiance_size, s.lights = room, 64, 16, 2
    bpy.ops.gs_ibl.bake_probe()
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.data.lens = 24
    scene.collection.objects.link(cam)
    S._look_at(bpy, cam, (1.9, -1.2, 1.5), (-0.2, 1.1, 0.3))
    scene.camera = cam
    r = scene.render
    r.engine, r.resolution_x, r.resolution_y = "CYCLES", 480, 270
    scene.cycles.samples, scene.cycles.use_denoising = 32, False
    r.image_settings.file_format = "OPEN_EXR"
    scene.view_settings.view_transform = "Standard"
    out = {}
    for state in (False, True):
        scene.gs_ibl_render.shadows = state
        out[state] = S.render(bpy, tmp / f"room_{int(state)}.exr")
    out["record"] = next(iter(frame.last_render(scene)["frames"].values()))
    return out


def _room_plot(room: dict, path: pathlib.Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    off, on = room[False], room[True]
    ratio = on[..., :3].sum(-1) / np.maximum(off[..., :3].sum(-1), 1e-6)
    fig, ax = plt.subplots(1, 3, figsize=(16, 3.4))
    ax[0].imshow(_tone(off[..., :3]))
    ax[0].set_title("sample room, F12 (Cycles): Shadows on Splats off", fontsize=10)
    ax[1].imshow(_tone(on[..., :3]))
    ax[1].set_title("on (lit by the baked probe: window, lamp and room)", fontsize=10)
    shown = ax[2].imshow(np.where(off[..., 3] > 0.5, ratio, np.nan), vmin=0.3, vmax=1.0, cmap="magma")
    ax[2].set_title(f"on / off ({room['record'].get('ms_shadows')} ms of shadows, 480x270)", fontsize=10)
    fig.colorbar(shown, ax=ax[2], fraction=0.03)
    for a in ax:
        a.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plots(c: dict, frames: tuple, sphere: np.ndarray, folder: pathlib.Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d_o, d_c, region = c["D_ours"], c["D_cycles"], c["region"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    m = region & np.isfinite(d_o) & np.isfinite(d_c)
    ax[0].scatter(d_c[m], d_o[m], s=2, alpha=0.3)
    top = float(np.nanmax(d_c[m])) if m.any() else 1.0
    ax[0].plot([0, top], [0, top], "k-", lw=1, label="equal")
    ax[0].plot([0, top], [0, 0.9 * top], "k:", lw=1, label="±10 %")
    ax[0].plot([0, top], [0, 1.1 * top], "k:", lw=1)
    ax[0].set_xlabel("D Cycles (3x3 box)")
    ax[0].set_ylabel("D ours (3x3 box)")
    ax[0].set_title(f"per pixel, shadowed region: D {c['d_ours']:.3f} ours, {c['d_cycles']:.3f} Cycles")
    ax[0].legend()
    rows = np.nonzero(region.any(1))[0]
    mid = int(rows[len(rows) // 2]) if len(rows) else d_o.shape[0] // 2
    ax[1].plot(d_c[mid], label="Cycles (diffuse plane, path traced)")
    ax[1].plot(d_o[mid], label="ours (splat floor)")
    ax[1].set_xlabel(f"column (row {mid})")
    ax[1].set_ylabel("darkening D")
    ax[1].set_title("one row through the shadow")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(folder / "shadow_bench.png", dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(1, 4, figsize=(16, 3.6))
    panels = [("ours: splat floor, Shadows on Splats", _tone(frames[0][..., :3])),
              ("Cycles: diffuse plane, path traced", _tone(frames[1][..., :3])),
              ("D ours", d_o), ("D Cycles", d_c)]
    for a, (title, im) in zip(ax, panels):
        if im.ndim == 2:
            shown = a.imshow(np.where(sphere, np.nan, im), vmin=0, vmax=0.9, cmap="magma")
            fig.colorbar(shown, ax=a, fraction=0.035)
        else:
            a.imshow(im)
        a.set_title(title, fontsize=10)
        a.axis("off")
    fig.tight_layout()
    fig.savefig(folder / "shadow_ours_vs_cycles.png", dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    main()
