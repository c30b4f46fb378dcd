"""Numbers and pictures of docs/stability.md: the failure catalogue (issue 17).

Run: python benchmarks/stability_bench.py order --save out/order_after.npz [--face 64] [--splats 20000]
     python benchmarks/stability_bench.py plot-order BEFORE.npz AFTER.npz --png docs/img/stability_order.png
     python benchmarks/stability_bench.py holes --png docs/img/stability_holes.png
     python benchmarks/stability_bench.py near --png docs/img/stability/near.png
     python benchmarks/stability_bench.py sh --png docs/img/stability/sh_ringing.png
     python benchmarks/stability_bench.py conv --png docs/img/stability/conv_box.png
     python benchmarks/stability_bench.py highlights --png docs/img/stability/highlights.png
     python benchmarks/stability_bench.py path --png docs/img/stability/path.png
     python benchmarks/stability_bench.py prune --png docs/img/stability/prune.png
     python benchmarks/stability_bench.py shadow --png docs/img/stability/shadow.png   (needs bpy: Cycles renders)

order: a closed shell (synthetic.shell_scene, radiance a + b d_z, exact irradiance known) stored in Morton order and
shuffled, baked at a fixed face size; prints the per-channel relative RMS error against the exact irradiance and
saves the irradiance error per direction (lat-long). Run it in a checkout before the tie rule (the "before" file)
and after; plot-order draws both.
holes: the room with an open window (synthetic.room_scene), probe at its centre and 7 m outside; irradiance with
holes left black, filled with the mean, and (the window only) the window closed by a wall of the fill's colour.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402

from gs_ibl_addon.core import cubemap, synthetic  # noqa: E402
from gs_ibl_addon.core.bake import ProbeSettings, bake_probe  # noqa: E402
from gs_ibl_addon.core.formats.compressed_ply import morton_order  # noqa: E402
from gs_ibl_addon.core.probe.latlong import cube_to_latlong  # noqa: E402

IRR = 16
LL = (128, 64)


def channel_rms(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sqrt(((a - b) ** 2).mean(axis=(0, 1, 2))) / np.sqrt((b ** 2).mean(axis=(0, 1, 2)))


def cmd_order(a) -> None:
    sky = synthetic.SkyGradient()
    shuffled = synthetic.shell_scene(sky, a.splats)
    scenes = {"ordered": shuffled.subset(morton_order(shuffled.positions)), "shuffled": shuffled}
    exact = sky.irradiance_over_pi(cubemap.face_directions(IRR).reshape(-1, 3)).reshape(6, IRR, IRR, 3)
    out = {}
    for name, scene in scenes.items():
        settings = ProbeSettings(face_size=a.face, irradiance_size=IRR)
        t = time.perf_counter()
        r = bake_probe(scene, (0, 0, 0), settings)
        wall = time.perf_counter() - t
        err = channel_rms(r.irradiance, exact)
        print(f"{name}: irradiance off exact (R, G, B) {np.round(100 * err, 3).tolist()} %, "
              f"face {r.settings['face_size']}, bake {wall:.1f} s")
        out[name] = cube_to_latlong((r.irradiance - exact) / exact, LL[0], LL[1])
        out[name + "_rms"] = err
    if a.save:
        os.makedirs(os.path.dirname(os.path.abspath(a.save)), exist_ok=True)
        np.savez(a.save, **out)


def cmd_plot_order(a) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs = [("before (ties keep storage order)", np.load(a.before)),
            ("after (ties by position hash)", np.load(a.after))]
    lim = max(float(np.abs(r[k][..., 2]).max()) for _, r in runs for k in ("ordered", "shuffled"))
    fig, axes = plt.subplots(2, 2, figsize=(9, 5), constrained_layout=True)
    for row, (label, r) in enumerate(runs):
        for col, name in enumerate(("ordered", "shuffled")):
            ax = axes[row, col]
            im = ax.imshow(100 * r[name][..., 2], cmap="RdBu_r", vmin=-100 * lim, vmax=100 * lim,
                           extent=(180, -180, -90, 90))
            rms = r[name + "_rms"]
            ax.set_title(f"{label}\n{'Morton-ordered' if name == 'ordered' else 'shuffled'} file: "
                         f"{100 * rms.max():.2f}% RMS", fontsize=9)
            ax.set_xlabel("azimuth (deg)", fontsize=8)
            ax.set_ylabel("elevation", fontsize=8)
            ax.tick_params(labelsize=7)
    fig.colorbar(im, ax=axes, shrink=0.8, label="irradiance error, blue channel (%)")
    fig.savefig(a.png, dpi=110)
    print(f"wrote {a.png}")


def window_panel(room, colour):
    """A wall of radiance ``colour`` 1 m outside the window, covering all it shows (tests/test_stability.py)."""
    (_, _, (u0, u1), (v0, v1)), = room.openings
    s, grow = room.sigma, 1.5
    yy, zz = np.meshgrid(np.arange(u0 * grow - 2 * s, u1 * grow + 2 * s, s),
                         np.arange(1.5 + (v0 - 1.5) * grow - 2 * s, 1.5 + (v1 - 1.5) * grow + 2 * s, s), indexing="ij")
    n = yy.size
    centres = np.stack([np.full(n, room.hi[0] + 1.0), yy.ravel(), zz.ravel()], -1)
    return synthetic._disks(centres, np.tile([-1.0, 0, 0], (n, 1)), np.tile(colour, (n, 1)), s, 0.05, 0.99)


def cmd_holes(a) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    room = synthetic.room_scene(skylight=None)
    inside, outside = (0, 0, 1.5), (10, 0, 1.5)
    s = dict(face_size=a.face, irradiance_size=IRR)
    bakes = {}
    for key, pos, fill in (("in_black", inside, "black"), ("in_mean", inside, "mean"),
                           ("out_black", outside, "black"), ("out_mean", outside, "mean")):
        t = time.perf_counter()
        r = bake_probe(room.scene, pos, ProbeSettings(hole_fill=fill, **s))
        bakes[key] = r
        print(f"{key}: holes {100 * r.hole_fraction:.2f}%, fill {r.hole_fill}, mean E/pi "
              f"{np.round(r.irradiance.mean((0, 1, 2)), 3).tolist()}, hole fill {r.timings_ms.get('hole_fill', 0):.0f} "
              f"ms of {time.perf_counter() - t:.2f} s")
    value = bakes["in_mean"].hole_fill["value"]
    closed = bake_probe(synthetic.concat([room.scene, window_panel(room, value)]), inside, ProbeSettings(**s))
    for key in ("in_black", "in_mean"):
        err = channel_rms(bakes[key].irradiance, closed.irradiance)
        print(f"{key} vs the window closed by a wall of the fill's colour: {np.round(100 * err, 3).tolist()} % RMS")
    fig, axes = plt.subplots(2, 3, figsize=(12, 4.6), constrained_layout=True)

    def show(ax, cube, title, contour=None, scale=None):
        ll = cube_to_latlong(np.asarray(cube)[..., :3], LL[0] * 2, LL[1] * 2)
        scale = scale or max(float(np.percentile(ll, 99)), 1e-6)
        ax.imshow(np.clip(ll / scale, 0, 1) ** (1 / 2.2), extent=(180, -180, -90, 90))
        if contour is not None:
            a_ll = cube_to_latlong(contour[..., 3:4], LL[0] * 2, LL[1] * 2)[..., 0]
            ax.contour(np.linspace(180, -180, a_ll.shape[1]), np.linspace(90, -90, a_ll.shape[0]), a_ll,
                       levels=[0.5], colors="magenta", linewidths=0.8)
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])

    ib, im, ob, om = bakes["in_black"], bakes["in_mean"], bakes["out_black"], bakes["out_mean"]
    show(axes[0, 0], ib.radiance, f"inside: radiance, window = hole ({100 * ib.hole_fraction:.1f}%, magenta)",
         ib.radiance)
    top, bottom = float(im.irradiance.max()), float(om.irradiance.max())  # one exposure per row
    off_black = 100 * channel_rms(ib.irradiance, closed.irradiance).max()
    off_mean = 100 * channel_rms(im.irradiance, closed.irradiance).max()
    show(axes[0, 1], ib.irradiance, f"irradiance, holes black: {off_black:.1f}% off", scale=top)
    show(axes[0, 2], im.irradiance, f"holes filled with the mean: {off_mean:.3f}% off\n"
                                    "(reference: window closed by a wall of that colour)", scale=top)
    show(axes[1, 0], ob.radiance, f"outside (10 m): radiance, {100 * ob.hole_fraction:.0f}% holes", ob.radiance)
    show(axes[1, 1], ob.irradiance, "irradiance, holes black (the old probe)", scale=bottom)
    show(axes[1, 2], om.irradiance, "holes filled with the mean (+ a loud warning)", scale=bottom)
    fig.savefig(a.png, dpi=100)
    print(f"wrote {a.png}")


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, png: str) -> None:
    os.makedirs(os.path.dirname(os.path.abspath(png)), exist_ok=True)
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")


def _wall_truth(room, p):
    """The closed room's radiance from p as flat walls of their colour (no splat blur): the probe's ground truth."""
    from gs_ibl_addon.core.probe.reference import cube_from_function, exact_irradiance_cube

    def radiance(d):
        ax, side, _ = room._hits(p, d)
        return np.array([synthetic.WALL_COLOURS[(a, s)] for a, s in zip(ax, side)])
    return exact_irradiance_cube(cube_from_function(radiance, 128), IRR, 32)


def cmd_near(a) -> None:
    """A probe moved toward the -X wall of a closed room: thin wall splats (the room's, 5 mm thick) and thick ones
    (isotropic, sigma = the 10 cm spacing, like a trained capture's fuzz); error against flat walls."""
    import dataclasses

    from gs_ibl_addon.core.bake import relative_rms
    from gs_ibl_addon.core.probe.near import near_splats
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    room = synthetic.room_scene(window=None, skylight=None)
    thick = dataclasses.replace(room.scene, scales=np.full_like(room.scene.scales, float(room.scene.scales.max())))
    dist = np.array([1.5, 1.0, 0.6, 0.4, 0.3, 0.2, 0.15, 0.1, 0.05, 0.02, 0.0])
    rows = {}
    for name, scene in (("thin", room.scene), ("thick", thick)):
        errs, sig = [], []
        with SplatRenderer(scene) as r:
            for d in dist:
                p = np.array([room.lo[0] + d, 0.3, 1.4])
                res = bake_probe(None, p, ProbeSettings(face_size=a.face, irradiance_size=IRR, hole_fill="black"),
                                 renderer=r)
                errs.append(channel_rms(res.irradiance, _wall_truth(room, p)).max())
                sig.append(near_splats(scene, p)["nearest_sigmas"])
                print(f"{name} wall, {d:.2f} m: {100 * errs[-1]:.1f}% RMS off flat walls, nearest splat "
                      f"{sig[-1]:.2f} sigma, holes {100 * res.hole_fraction:.1f}%", flush=True)
        rows[name] = (np.array(errs), np.array(sig))
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    for name, (errs, sig) in rows.items():
        axes[0].plot(dist, 100 * errs, "o-", label=f"{name} wall splats")
        axes[1].semilogx(np.maximum(sig, 1e-2), 100 * errs, "o", label=f"{name} wall splats")
    axes[0].set_xlabel("probe's distance from the wall's splat centres (m)")
    axes[0].set_ylabel("irradiance RMS off flat walls (%)")
    axes[1].axvline(3.0, color="grey", ls="--", label="warning: within 3 sigma")
    axes[1].set_xlabel("distance to the nearest splat in its sigmas (Mahalanobis)")
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(f"probe approaching a wall (closed room, {a.face}^2 faces)", fontsize=10)
    _save(fig, a.png)


def _sun_cube(ratio: float, size: int = 256):
    from gs_ibl_addon.core.probe.reference import cube_from_function
    omega = 2 * np.pi * (1 - np.cos(np.radians(2.0)))
    sun = synthetic.BrightPatch(radius_deg=2.0, intensity=ratio * np.pi / omega, colour=(1.0, 1.0, 1.0))
    return cube_from_function(sun, size), sun


def cmd_sh(a) -> None:
    """SH order 2 next to a 2-degree sun whose irradiance is 1-100x the sky's: unclamped minimum, error, windows,
    and SH of the rest with the sun split off as a light."""
    from gs_ibl_addon.core.bake import relative_rms
    from gs_ibl_addon.core.probe.lights import extract_lights, lights_irradiance
    from gs_ibl_addon.core.probe.reference import exact_irradiance, exact_irradiance_cube
    from gs_ibl_addon.core.probe.sh_project import project_cube, sh_irradiance
    variants = (("none", None), ("hanning", 5), ("lanczos", 6))
    normals = cubemap.face_directions(IRR)
    for ratio in (1, 3, 10, 30, 100):
        cube, _ = _sun_cube(ratio)
        exact = exact_irradiance_cube(cube, IRR, 64)
        c = project_cube(cube, 2)
        out = [f"sun/sky {ratio:>3}:"]
        for w, width in variants:
            e = sh_irradiance(c, normals, w, width, clamp=False)
            out.append(f"{w} min {e.min():+.2f} rms {100 * relative_rms(np.maximum(e, 0), exact):.1f}%")
        rest, lights = extract_lights(cube, 1)
        e = sh_irradiance(project_cube(rest, 2), normals) + lights_irradiance(lights, normals)
        out.append(f"split: rms {100 * relative_rms(e, exact):.2f}% (exact {exact.min():.2f}..{exact.max():.1f})")
        print("; ".join(out), flush=True)
    cube, sun = _sun_cube(30)
    sd = np.asarray(sun.direction) / np.linalg.norm(sun.direction)
    perp = np.cross(sd, [0, 0, 1.0])
    perp /= np.linalg.norm(perp)
    ang = np.linspace(0, 180, 181)
    nrm = np.cos(np.radians(ang))[:, None] * sd + np.sin(np.radians(ang))[:, None] * perp
    exact = exact_irradiance(cube, nrm)[:, 1]
    c = project_cube(cube, 2)
    rest, lights = extract_lights(cube, 1)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4), constrained_layout=True)
    ax.plot(ang, exact, "k", lw=2, label="exact")
    for w, width in variants:
        ax.plot(ang, sh_irradiance(c, nrm, w, width, clamp=False)[:, 1], label=f"SH 2, window {w}"
                + (f" (width {width})" if width else ""))
    split = sh_irradiance(project_cube(rest, 2), nrm, clamp=False) + lights_irradiance(lights, nrm)
    ax.plot(ang, split[:, 1], "--", label="SH 2 of the rest + the sun as a light")
    ax.axhline(0, color="grey", lw=0.5)
    ax.set_xlabel("angle of the normal from the sun (deg)")
    ax.set_ylabel("E/pi (unclamped)")
    ax.set_ylim(-0.5, 3)
    ax.legend(fontsize=8)
    ax.set_title("2-degree sun, irradiance 30x the sky's: SH order 2 rings negative behind it", fontsize=10)
    _save(fig, a.png)


def cmd_conv(a) -> None:
    """conv's arcs (reading the full cube vs the copy matched to the grid) and box's error, 7-degree sun."""
    from gs_ibl_addon.core.bake import relative_rms
    from gs_ibl_addon.core.probe.box import box_irradiance
    from gs_ibl_addon.core.probe.convolve import cosine_convolve, hemisphere_grid
    from gs_ibl_addon.core.probe.reference import (cube_from_function, exact_irradiance_cube, tangent_frames,
                                                   to_world)
    from gs_ibl_addon.core.probe.sampling import sample_cube_bilinear
    size = a.irr
    maps = {}
    for label, fn in (("sun", synthetic.BrightPatch()), ("sky", synthetic.SkyGradient()),
                      ("walls", synthetic.ColouredWalls())):
        cube = cube_from_function(fn, 128)
        exact = exact_irradiance_cube(cube, size)
        local, w = hemisphere_grid(64, 16)
        normals = cubemap.face_directions(size).reshape(-1, 3)
        t, b = tangent_frames(normals)
        full = np.concatenate([np.einsum("s,msc->mc", w, sample_cube_bilinear(cube, to_world(local, t[k:k + 64],
                               b[k:k + 64], normals[k:k + 64]))) for k in range(0, len(normals), 64)])
        full = full.reshape(exact.shape)
        matched = cosine_convolve(cube, size, 64, 16)
        row = {"conv 64x16, full cube": full, "conv 64x16, matched copy": matched}
        for level in (1, size):
            row[f"box, level {level}"] = box_irradiance(cube, size, level)
        print(label + ": " + ", ".join(f"{k} {100 * relative_rms(v, exact):.2f}% (max "
                                        f"{100 * np.abs((v - exact) / exact).max():.1f}%)" for k, v in row.items()),
              flush=True)
        if label == "sun":
            maps = {k: (v - exact) / exact for k, v in row.items() if k.startswith("conv")}
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3), constrained_layout=True)
    lim = max(float(np.abs(m[..., 1]).max()) for m in maps.values())
    for ax, (k, m) in zip(axes, maps.items()):
        im = ax.imshow(100 * cube_to_latlong(m, 4 * size, 2 * size)[..., 1], cmap="RdBu_r", vmin=-100 * lim,
                       vmax=100 * lim, extent=(180, -180, -90, 90))
        ax.set_title(f"{k}: error vs exact (green, %)", fontsize=9)
    fig.colorbar(im, ax=axes, shrink=0.8)
    _save(fig, a.png)


def cmd_highlights(a) -> None:
    """A shell with a sun of radiance 60 stored clipped at 1.0: irradiance of the float shell, the clipped one, the
    clipped one with the gain on the splats and on the cube, auto; the sun split off as a light."""
    from gs_ibl_addon.core.bake import relative_rms
    from gs_ibl_addon.core.probe.lights import lights_irradiance
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    sun = synthetic.BrightPatch(intensity=120.0, colour=(1.0, 1.0, 1.0))
    flt = synthetic.shell_scene(sun, a.splats)
    clp = synthetic.shell_scene(lambda d: np.minimum(sun(d), 1.0), a.splats)
    s = dict(face_size=a.face, irradiance_size=IRR)
    ref = bake_probe(flt, (0, 0, 0), ProbeSettings(**s))
    runs = {"clipped": bake_probe(clp, (0, 0, 0), ProbeSettings(**s)),
            "gain 60 on the splats": bake_probe(clp, (0, 0, 0), ProbeSettings(highlight_gain=60.0, **s)),
            "gain auto": bake_probe(clp, (0, 0, 0), ProbeSettings(highlight_gain="auto", **s))}
    with SplatRenderer(clp) as r:
        runs["gain 60 on the cube"] = bake_probe(None, (0, 0, 0), ProbeSettings(highlight_gain=60.0, **s), renderer=r)
    for k, v in runs.items():
        print(f"{k}: {100 * relative_rms(v.irradiance, ref.irradiance):.2f}% RMS off the float shell; {v.highlights}")
    split = bake_probe(flt, (0, 0, 0), ProbeSettings(lights=1, **s))
    normals = cubemap.face_directions(IRR)
    total = split.irradiance + lights_irradiance(split.lights, normals)
    print(f"lights: {split.lights}; rest + light {100 * relative_rms(total, ref.irradiance):.2f}% off the whole")
    plt = _plt()
    fig, axes = plt.subplots(2, 3, figsize=(12, 4.6), constrained_layout=True)
    top = float(ref.irradiance.max())

    def show(ax, cube, title, scale):
        ll = cube_to_latlong(np.asarray(cube)[..., :3], LL[0] * 2, LL[1] * 2)
        ax.imshow(np.clip(ll / scale, 0, 1) ** (1 / 2.2), extent=(180, -180, -90, 90))
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    show(axes[0, 0], runs["clipped"].radiance, "radiance stored clipped at 1.0 (exposure x1)", 1.0)
    show(axes[0, 1], ref.irradiance, "irradiance: float capture (sun 60)", top)
    off = 100 * relative_rms(runs["clipped"].irradiance, ref.irradiance)
    show(axes[0, 2], runs["clipped"].irradiance, f"clipped: {off:.0f}% off", top)
    for ax, k in zip(axes[1], ("gain 60 on the splats", "gain 60 on the cube")):
        show(ax, runs[k].irradiance, f"{k}: {100 * relative_rms(runs[k].irradiance, ref.irradiance):.2g}% off",
             top)
    show(axes[1, 2], split.irradiance, f"the World's part with the sun split off as a light\n"
                                       f"({100 * split.lights[0]['share']:.0f}% of the light, "
                                       f"{split.lights[0]['angle']:.0f} deg across)", top)
    _save(fig, a.png)


def cmd_path(a) -> None:
    """The probe moved in 10 cm steps along y through the sample room (x 0.3, z 1.2), fixed faces and the search;
    then splats pruned 5% at a time, least opaque first."""
    from gs_ibl_addon.core.bake import relative_rms
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    env = synthetic.sample_environment()
    ys = np.linspace(-2.0, 2.0, 41)
    curves = {}
    with SplatRenderer(env) as r:
        for name, st in (("64^2", dict(face_size=64)), ("128^2", dict(face_size=128)),
                         ("auto (1%)", dict(face_size=0))):
            irr, faces = [], []
            t = time.perf_counter()
            for y in ys:
                res = bake_probe(None, (0.3, y, 1.2), ProbeSettings(irradiance_size=IRR, **st), renderer=r)
                irr.append(res.irradiance)
                faces.append(res.settings["face_size"])
            steps = np.array([relative_rms(q, p) for p, q in zip(irr, irr[1:])])
            span = relative_rms(irr[-1], irr[0])
            print(f"{name}: step-to-step change max {100 * steps.max():.2f}%, median {100 * np.median(steps):.2f}% "
                  f"(max/median {steps.max() / np.median(steps):.2f}); end to end {100 * span:.1f}%; faces "
                  f"{sorted(set(faces))}; {time.perf_counter() - t:.0f} s", flush=True)
            curves[name] = (steps, np.array([x.mean((0, 1, 2)) for x in irr]))
    order = np.argsort(env.opacities)
    kept, prune = [], np.arange(0, 0.51, 0.05)
    for f in prune:
        sub = env.subset(np.sort(order[int(f * env.count):]))
        kept.append(bake_probe(sub, (0.3, 0.0, 1.2), ProbeSettings(face_size=64, irradiance_size=IRR)))
    psteps = np.array([relative_rms(q.irradiance, p.irradiance) for p, q in zip(kept, kept[1:])])
    print("pruned (least opaque first), 5% steps: change per step " + ", ".join(f"{100 * v:.2f}%" for v in psteps)
          + "; holes " + ", ".join(f"{100 * k.hole_fraction:.1f}%" for k in kept))
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    for name, (steps, mean) in curves.items():
        axes[0].plot(ys, mean[:, 0], label=f"{name} (red)")
        axes[1].plot((ys[1:] + ys[:-1]) / 2, 100 * steps, label=name)
    axes[0].set_xlabel("probe y (m)")
    axes[0].set_ylabel("mean E/pi")
    axes[1].set_xlabel("probe y (m)")
    axes[1].set_ylabel("change from the previous 10 cm step (% RMS)")
    axes[2].plot(100 * prune[1:], 100 * psteps, "o-")
    axes[2].set_xlabel("splats pruned, least opaque first (%)")
    axes[2].set_ylabel("change from the previous 5% (% RMS)")
    for ax in axes[:2]:
        ax.legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    _save(fig, a.png)


def cmd_prune(a) -> None:
    """The sample room's probe (0.3, 0, 1.2) with splats pruned 5% at a time in a random order (the room's
    opacities are all 0.99, so "least opaque first" would be storage order and take whole walls at once)."""
    from gs_ibl_addon.core.bake import relative_rms
    env = synthetic.sample_environment()
    order = np.random.default_rng(0).permutation(env.count)
    prune = np.arange(0, 0.51, 0.05)
    kept = []
    for f in prune:
        sub = env.subset(np.sort(order[int(round(f * env.count)):]))
        kept.append(bake_probe(sub, (0.3, 0.0, 1.2), ProbeSettings(face_size=a.face, irradiance_size=IRR)))
    steps = np.array([relative_rms(q.irradiance, p.irradiance) for p, q in zip(kept, kept[1:])])
    holes = np.array([k.hole_fraction for k in kept])
    print("pruned at random, 5% steps: change per step " + ", ".join(f"{100 * v:.2f}%" for v in steps)
          + "; holes " + ", ".join(f"{100 * h:.1f}%" for h in holes) + "; off the full room "
          + ", ".join(f"{100 * relative_rms(k.irradiance, kept[0].irradiance):.1f}%" for k in kept))
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.4), constrained_layout=True)
    ax.plot(100 * prune[1:], 100 * steps, "o-", label="change from the previous 5% (% RMS)")
    ax.plot(100 * prune, 100 * holes, "s--", label="holes (% of the sphere, filled with the mean)")
    ax.set_xlabel("splats pruned at random (%)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, a.png)


def cmd_shadow(a) -> None:
    """Cycles (bpy): a white sphere on a grey floor in the sun shell, lit by the probe alone and by the probe with
    its sun split off as a Blender sun (shadows)."""
    import math

    import bpy

    import gs_ibl_addon
    from gs_ibl_addon.blender.lighting.bake import bake_into_world
    from gs_ibl_addon.blender.splats.object import create_splat_object
    sun = synthetic.BrightPatch(intensity=120.0, colour=(1.0, 1.0, 1.0))
    shell = synthetic.shell_scene(sun, 20000)
    images = []
    for lights in (0, 1):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        try:
            scene.render.engine = a.engine
        except TypeError:  # Blender 4.2-4.x: BLENDER_EEVEE_NEXT
            scene.render.engine = a.engine + "_NEXT"
        scene.cycles.samples, scene.cycles.device = a.samples, "CPU"
        scene.eevee.taa_render_samples = a.samples
        scene.render.resolution_x, scene.render.resolution_y = 320, 200
        scene.view_settings.view_transform = "Standard"
        bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0, 0, -0.5))
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0, 0, 0))
        bpy.ops.object.shade_smooth()
        for obj, grey in ((bpy.data.objects["Plane"], 0.5), (bpy.data.objects["Sphere"], 0.8)):
            mat = bpy.data.materials.new(obj.name)
            mat.use_nodes = True
            mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (grey, grey, grey, 1)
            mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 1.0
            obj.data.materials.append(mat)
        cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
        cam.location = (3.2, 2.4, 1.6)
        cam.rotation_euler = (math.radians(72), 0, math.radians(127))
        scene.collection.objects.link(cam)
        scene.camera = cam
        gs_ibl_addon.register()
        try:
            splats = create_splat_object(bpy.context, shell, "shell", proxy=False)
            probe = bpy.data.objects.new("GS-IBL Probe", None)
            s = probe.gs_ibl_probe
            s.is_probe, s.splats, s.face_size, s.keep_background, s.lights = True, splats, 64, True, lights
            scene.collection.objects.link(probe)
            _, text, _ = bake_into_world(scene, probe)
            print(text)
        finally:
            gs_ibl_addon.unregister()
        path = f"/tmp/stability_shadow_{lights}.png"
        scene.render.filepath = path
        scene.render.image_settings.file_format = "PNG"
        bpy.ops.render.render(write_still=True)
        images.append(path)
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.4), constrained_layout=True)
    for ax, path, title in zip(axes, images, (f"{a.engine}: the probe alone (the sun is in the World)",
                                              f"{a.engine}: Lights 1 (the World keeps the rest, the sun is a light)")):
        ax.imshow(plt.imread(path))
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    _save(fig, a.png)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    q = sub.add_parser("order")
    q.add_argument("--splats", type=int, default=20000)
    q.add_argument("--face", type=int, default=64)
    q.add_argument("--save")
    q.set_defaults(fn=cmd_order)
    q = sub.add_parser("plot-order")
    q.add_argument("before")
    q.add_argument("after")
    q.add_argument("--png", default="docs/img/stability_order.png")
    q.set_defaults(fn=cmd_plot_order)
    q = sub.add_parser("holes")
    q.add_argument("--face", type=int, default=64)
    q.add_argument("--png", default="docs/img/stability_holes.png")
    q.set_defaults(fn=cmd_holes)
    for name, fn, extra in (("near", cmd_near, {"face": 64}), ("sh", cmd_sh, {}), ("conv", cmd_conv, {"irr": 16}),
                            ("highlights", cmd_highlights, {"face": 64, "splats": 20000}), ("path", cmd_path, {}),
                            ("prune", cmd_prune, {"face": 64}), ("shadow", cmd_shadow, {"samples": 64})):
        q = sub.add_parser(name)
        for opt, default in extra.items():
            q.add_argument(f"--{opt}", type=int, default=default)
        if name == "shadow":
            q.add_argument("--engine", default="CYCLES", help="CYCLES or BLENDER_EEVEE")
        q.add_argument("--png", default=f"docs/img/stability/{name}.png")
        q.set_defaults(fn=fn)
    a = ap.parse_args()
    a.fn(a)


if __name__ == "__main__":
    main()
