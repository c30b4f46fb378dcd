"""Numbers and pictures of docs/stability.md: storage-order bias and holes (issue 17).

Run: python benchmarks/stability_bench.py order --save out/order_after.npz [--face 64] [--splats 20000]
     python benchmarks/stability_bench.py plot-order BEFORE.npz AFTER.npz --png docs/img/stability_order.png
     python benchmarks/stability_bench.py holes --png docs/img/stability_holes.png

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
    a = ap.parse_args()
    a.fn(a)


if __name__ == "__main__":
    main()
