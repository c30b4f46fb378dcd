"""Issue 37, a study: a probe's light at other places from one rendered cube with depth, reprojected (parallax).

Run:  .venv/bin/python benchmarks/reprojection_study.py [--points 64] [--target 64] [--faces 64,128,256]
      [--out-csv docs/bench/reprojection_lavapipe.csv] [--png docs/img/reprojection_study.png]

The sample room (samples/room.ply) with volume_bench's white spheres (r 0.25) at auto_light_bench's five places,
--points shading points each (Fibonacci, normals outward). The reference is volume_bench.reference: each point's own
rendered 32^2 cube, integrated exactly against the cosine lobe. Against it:
- world: the World probe's order-2 SH at auto_light_bench's PROBE (as volume_bench's accuracy row);
- source cube, no parallax: the 128^2 source cube itself at every point (its exact irradiance; what SH truncation
  costs, without parallax);
- reproj F: the cube at PROBE with depth, F^2 faces; each texel -> the world point it sees (origin + direction x
  distance); per shading point x every such point is forward-warped into a target cube of --target^2 faces (direction
  (p - x)/|p - x|, distance |p - x|) under a z-test, then integrated by the same exact cosine integral as the
  reference (core.probe.reference.exact_irradiance); "hole": the solid-angle share of target texels no source point
  reached. "point": each source texel lands in one target texel; "splat": each covers a square of the solid angle its
  surface patch subtends from x (its solid angle x D^2 / cos at the source, x cos at x / d^2, with normals from the
  depth). The z-test keeps, per target texel, the points within DEPTH_TOL of the nearest and averages them by the
  solid angle each covers from x (the nearest alone dilates whatever sticks out, a lamp over its ceiling, by a target
  texel); source texels whose surface faces away from x are dropped (normals from the depth); unreached target texels
  are first grown over from their reached neighbours (GROW rings), the rest take the infinite-distance guess;
- 32^2 target, holes at infinity (no growing), no z-test (every source texel landing in a target texel counts,
  their mean): what each part is worth;
- +8 corners: the cube at PROBE and cubes at the 8 corners of the box around the five spheres (inset 0.1 m), all
  warped under one z-test, or one at a time nearest to x first, each filling only what the nearer left empty;
  + mesh centre: the cube at PROBE and one at the sphere's own centre, nearest first;
- hybrid: "reproj 128 splat" with the points whose hole share is above a threshold given the reference (a real
  probe there); its hole column is the share of points that took a probe.
Cost: the source renders, the reprojection per point (numpy) and the reference's per-point cubes, in the same run,
with the load average; the World probe's bake as the panel does it, for issue 37's <= 2x target.

Helpers that would belong in core if this were built (core/probe): source_points (a cube with depth -> world
points) and reproject (world points -> a cube at another place, z-tested).
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
sys.path.insert(0, HERE)
from auto_light_bench import PLACES, PROBE  # noqa: E402
from volume_bench import boxes_of, centre, errors, reference, sphere_points  # noqa: E402

from gs_ibl_addon.core.bake import ProbeSettings, bake_probe  # noqa: E402
from gs_ibl_addon.core.cubemap import FACE_BASES, direction_to_face, face_directions, texel_solid_angles  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe.auto_light import measure_bake  # noqa: E402
from gs_ibl_addon.core.probe.grid import eval_irradiance  # noqa: E402
from gs_ibl_addon.core.probe.reference import exact_irradiance  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.render.views import ViewBatch  # noqa: E402

ALPHA_HOLE = 0.05  # a source texel with less coverage sees nothing (it is not warped)
EDGE_TOL = 0.0  # > 0: a source texel whose 1/depth bends by more than this (relative) is an edge, not warped
# (measured: dropping them at 0.003-0.03 leaves holes that cost more than the floating points they remove)
GROW = 8  # rings of target texels a hole is filled from its neighbours before the infinite-distance guess
DEPTH_TOL = 0.1  # the z-test's relative depth slack: points this much beyond the nearest still count (same surface)
MAX_SPAN = 16  # a splat covers at most MAX_SPAN^2 target texels (a source texel 16x magnified or more)


class Source:
    """One rendered cube with depth, as world points: ``cube`` (6, N, N, 4) premultiplied RGBA, and per texel that
    sees something (alpha >= ALPHA_HOLE) ``points`` (K, 3), ``rgb`` (K, 3) and ``area`` (K,): its solid angle x its
    distance^2 (the surface patch it covers, taken facing the origin)."""

    def __init__(self, r: SplatRenderer, origin, face: int, edge_tol: float | None = None) -> None:
        self.origin = np.asarray(origin, np.float64)
        t0 = time.perf_counter()
        res = r.render(ViewBatch.cubemap(self.origin, face), depth=True)
        self.cube = np.stack(res.images).astype(np.float64)
        depth = np.stack(res.depths).astype(np.float64)
        self.render_s = time.perf_counter() - t0
        dirs = face_directions(face)
        # the depth is the coverage-weighted distance along each face's view axis (gs_raster.glsl): along the ray it
        # is that over the direction's forward component
        fwd = np.einsum("fijc,fc->fij", dirs, FACE_BASES[:, 0])
        dist = depth / fwd
        seen = self.cube[..., 3] >= ALPHA_HOLE
        self.edges = _depth_edges(depth, EDGE_TOL if edge_tol is None else edge_tol)
        seen &= ~self.edges
        grid = self.origin + dirs * dist[..., None]
        nrm = _normals(grid, self.origin)
        self.points = grid[seen]
        self.normals = nrm[seen]
        self.rgb = self.cube[..., :3][seen]
        sa = np.broadcast_to(texel_solid_angles(face), (6, face, face))
        # the patch's area: its solid angle x distance^2 over the cosine at which the origin sees it (floored: a
        # surface seen edge-on from the origin is a thin sliver whose normal is poorly known)
        cos_s = np.maximum(np.abs(np.einsum("kc,kc->k", self.normals, dirs[seen])), 0.2)
        self.area = sa[seen] * dist[seen] ** 2 / cos_s


def _depth_edges(depth: np.ndarray, tol: float) -> np.ndarray:
    """(6, N, N) texels at a depth edge: there the coverage-weighted depth blends the near and the far surface and
    its world point floats between them, hiding from other places what lies behind. On a plane 1/z is linear across
    a face, so its second difference, relative to 1/z, is ~0 on any plane however grazing and large at an edge."""
    if not tol > 0:
        return np.zeros(depth.shape, bool)
    inv = 1.0 / np.maximum(depth, 1e-6)
    pad = np.pad(inv, ((0, 0), (1, 1), (1, 1)), mode="edge")
    d2s = np.abs(pad[:, 1:-1, 2:] - 2 * inv + pad[:, 1:-1, :-2])
    d2t = np.abs(pad[:, 2:, 1:-1] - 2 * inv + pad[:, :-2, 1:-1])
    return np.maximum(d2s, d2t) > tol * inv


def _normals(grid: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(6, N, N, 3) world points of a cube's texels -> unit normals facing the origin, from the smaller one-sided
    difference across and down each face (so a depth edge does not bend them; as the shadows' receivers do)."""
    def smaller(a: np.ndarray, axis: int) -> np.ndarray:
        fwd = np.diff(a, axis=axis, append=np.take(a, [-1], axis=axis))
        bwd = np.diff(a, axis=axis, prepend=np.take(a, [0], axis=axis))
        fwd_len, bwd_len = np.linalg.norm(fwd, axis=-1), np.linalg.norm(bwd, axis=-1)
        pick = ((fwd_len <= bwd_len) & (fwd_len > 0)) | (bwd_len == 0)
        return np.where(pick[..., None], fwd, bwd)
    n = np.cross(smaller(grid, 2), smaller(grid, 1))
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    flip = np.einsum("fijc,fijc->fij", n, origin - grid) < 0
    return np.where(flip[..., None], -n, n)


def _texel(face: np.ndarray, s: np.ndarray, t: np.ndarray, n: int) -> np.ndarray:
    i = np.clip(((s + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    j = np.clip(((t + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    return (face * n + j) * n + i


def _splat(face, s, t, omega, n):
    """Each point's square footprint of solid angle ``omega`` on its face (clipped at the face's edge: a footprint
    across a cube edge loses its part on the next face) -> (point index per copy, texel index per copy)."""
    c = 1.0 / np.sqrt(1.0 + s * s + t * t)  # the direction's forward component: dOmega = c^3 ds dt
    h = 0.5 * np.sqrt(omega / c ** 3)  # half-width in s, t
    i0 = np.clip(np.ceil((s - h + 1) * 0.5 * n - 0.5), 0, n - 1).astype(np.int64)
    i1 = np.clip(np.floor((s + h + 1) * 0.5 * n - 0.5), 0, n - 1).astype(np.int64)
    j0 = np.clip(np.ceil((t - h + 1) * 0.5 * n - 0.5), 0, n - 1).astype(np.int64)
    j1 = np.clip(np.floor((t + h + 1) * 0.5 * n - 0.5), 0, n - 1).astype(np.int64)
    small = (i1 < i0) | (j1 < j0)  # smaller than a texel: the texel it falls in
    ic = np.clip(((s + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    jc = np.clip(((t + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    i0, i1 = np.where(small, ic, i0), np.where(small, ic, i1)
    j0, j1 = np.where(small, jc, j0), np.where(small, jc, j1)
    ni = np.minimum(i1 - i0 + 1, MAX_SPAN)
    nj = np.minimum(j1 - j0 + 1, MAX_SPAN)
    i0 = np.where(i1 - i0 + 1 > MAX_SPAN, (i0 + i1 + 1) // 2 - MAX_SPAN // 2, i0)
    j0 = np.where(j1 - j0 + 1 > MAX_SPAN, (j0 + j1 + 1) // 2 - MAX_SPAN // 2, j0)
    copies = ni * nj
    who = np.repeat(np.arange(len(s)), copies)
    local = np.arange(len(who)) - np.repeat(np.cumsum(copies) - copies, copies)
    ii = i0[who] + local % ni[who]
    jj = j0[who] + local // ni[who]
    return who, (face[who] * n + jj) * n + ii


def _warp(sources: list[Source], x: np.ndarray, n: int, footprint: bool, ztest: bool, cull: bool,
          depth_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The sources' points warped to a cube at ``x``: (6 n n, 3) radiance and (6 n n,) reached (see reproject)."""
    pts = np.concatenate([s.points for s in sources])
    rgb = np.concatenate([s.rgb for s in sources])
    v = pts - x
    d = np.maximum(np.linalg.norm(v, axis=1), 1e-6)
    cos_t = -np.einsum("kc,kc->k", np.concatenate([s.normals for s in sources]), v) / d
    keep = cos_t > 0 if cull else np.ones(len(d), bool)
    v, d, rgb, cos_t = v[keep], d[keep], rgb[keep], np.abs(cos_t[keep])
    face, s, t = direction_to_face(v)
    area = np.concatenate([s_.area for s_ in sources])[keep]
    omega = area * cos_t / d ** 2  # the solid angle the patch subtends from x
    if footprint:
        who, tex = _splat(face, s, t, omega, n)
        counts = np.bincount(who, minlength=len(d))
        weight = omega[who] / counts[who]
    else:
        who, tex = np.arange(len(d)), _texel(face, s, t, n)
        weight = omega
    out = np.zeros((6 * n * n, 3))
    if ztest:
        near = np.full(6 * n * n, np.inf)
        np.minimum.at(near, tex, d[who])
        ok = d[who] <= near[tex] * (1 + depth_tol)
        who, tex, weight = who[ok], tex[ok], weight[ok]
    wsum = np.bincount(tex, weight, minlength=6 * n * n)
    for c in range(3):
        out[:, c] = np.bincount(tex, weight * rgb[who, c], minlength=6 * n * n)
    hit = wsum > 0
    out[hit] /= wsum[hit, None]
    return out, hit


def reproject(sources: list[Source], x: np.ndarray, n: int, footprint: bool = True, ztest: bool = True,
              cull: bool = True, depth_tol: float = DEPTH_TOL, grow: int = GROW,
              merge: str = "fill") -> tuple[np.ndarray, float]:
    """The cube (6, n, n, 4) that a probe at ``x`` would see, from the sources' world points, and the solid-angle
    share of its texels no point reached (filled from the first source's cube along the same direction).

    Per target texel the z-test keeps the points within ``depth_tol`` (relative) of the nearest and averages them
    weighted by the solid angle each covers from ``x``: several source texels of one surface fall in one target
    texel, and keeping only the nearest of them favours whatever sticks out (a lamp over its ceiling). ``cull``:
    points whose surface faces away from ``x`` are dropped (``x`` sees that surface's back, which no cube saw).
    Several sources: ``merge="fill"`` warps them one at a time, nearest to ``x`` first, each filling only what the
    nearer ones left empty; ``"ztest"`` warps them all together under one z-test (every source's floating points
    at its own depth edges, and its own view of view-dependent colour, then compete for every texel)."""
    if merge == "ztest" or len(sources) == 1:
        out, hit = _warp(sources, x, n, footprint, ztest, cull, depth_tol)
    else:
        order = sorted(sources, key=lambda s_: float(np.linalg.norm(s_.origin - x)))
        out, hit = np.zeros((6 * n * n, 3)), np.zeros(6 * n * n, bool)
        for src_ in order:
            o, h = _warp([src_], x, n, footprint, ztest, cull, depth_tol)
            new = h & ~hit
            out[new], hit = o[new], hit | h
    hole = hit.copy()  # the share reported: what no point reached, before the holes are grown over
    out, hit = _grow(out.reshape(6, n, n, 3), hit.reshape(6, n, n), grow)
    out, hit = out.reshape(-1, 3), hit.reshape(-1)
    dirs = face_directions(n).reshape(-1, 3)
    if not hit.all():
        src = sources[0].cube
        out[~hit] = src[..., :3][_unflat(_texel(*direction_to_face(dirs[~hit]), src.shape[1]), src.shape[1])]
    sa = np.broadcast_to(texel_solid_angles(n), (6, n, n)).reshape(-1)
    hole = float(sa[~hole].sum() / (4 * np.pi))
    cube = np.concatenate([out, np.ones((len(out), 1))], 1).reshape(6, n, n, 4)
    return cube, hole


def _grow(rgb: np.ndarray, hit: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Fill holes from their reached neighbours on the same face (mean of the 4-neighbours reached), ``steps``
    rings deep: a hole next to a surface is most likely more of it (a magnified texel's gaps, a disoccluded
    strip), where the infinite-distance guess would put whatever the source saw far behind."""
    for _ in range(steps):
        if hit.all():
            break
        acc = np.zeros_like(rgb)
        cnt = np.zeros(hit.shape)
        for axis, sh in ((1, 1), (1, -1), (2, 1), (2, -1)):
            m = np.roll(hit, sh, axis)
            edge = [slice(None)] * 3
            edge[axis] = 0 if sh == 1 else -1
            m[tuple(edge)] = False  # no wrap-around across the face
            acc += np.where(m[..., None], np.roll(rgb, sh, axis), 0)
            cnt += m
        new = ~hit & (cnt > 0)
        rgb = np.where(new[..., None], acc / np.maximum(cnt, 1)[..., None], rgb)
        hit = hit | new
    return rgb, hit


def _unflat(idx: np.ndarray, n: int):
    return idx // (n * n), (idx // n) % n, idx % n


def reprojected(sources: list[Source], pts: np.ndarray, nrm: np.ndarray, n: int,
                **kw) -> tuple[np.ndarray, np.ndarray, float]:
    """E/pi at each point from its reprojected cube; each point's hole share; seconds per point."""
    out = np.empty((len(pts), 3))
    holes = []
    t0 = time.perf_counter()
    for k, (x, nn) in enumerate(zip(pts, nrm)):
        cube, hole = reproject(sources, x, n, **kw)
        out[k] = exact_irradiance(cube, nn[None])[0, :3]
        holes.append(hole)
    return out, np.array(holes), (time.perf_counter() - t0) / len(pts)


def corners() -> list[np.ndarray]:
    lo = np.min([b[0] for b in boxes_of(PLACES)], 0) + 0.1
    hi = np.max([b[1] for b in boxes_of(PLACES)], 0) - 0.1
    return [np.array([(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]) for i in (0, 1) for j in (0, 1) for k in (0, 1)]


def study(r: SplatRenderer, scene, n_points: int, target: int, faces) -> tuple[list[dict], list[dict]]:
    load0 = os.getloadavg()[0]
    data = {p: sphere_points(p, n_points) for p in PLACES}
    # cost peers first, warm: the World probe's bake as the panel does it, then the per-point references
    bake_probe(None, np.asarray(PROBE, np.float64), ProbeSettings(), renderer=r, host_splats=scene)
    t0 = time.perf_counter()
    bake_probe(None, np.asarray(PROBE, np.float64), ProbeSettings(), renderer=r, host_splats=scene)
    world_bake_s = time.perf_counter() - t0
    reference(r, *data["centre"][:2])  # warm
    t0 = time.perf_counter()
    refs = {p: reference(r, *data[p][:2]) for p in PLACES}
    ref_s = (time.perf_counter() - t0) / (len(PLACES) * n_points)
    print(f"World probe bake {world_bake_s:.3f} s; reference: {ref_s * 1e3:.1f} ms per point "
          f"({len(PLACES) * n_points} points, {REF_FACE_NOTE})", flush=True)
    d_world = measure_bake(r)(np.asarray(PROBE, np.float64)[None])[0]

    main = {f: Source(r, PROBE, f) for f in faces}
    main = {f: Source(r, PROBE, f) for f in faces}  # again, warm: the timed render
    corner_src = [Source(r, c, 128) for c in corners()]
    costs = [{"what": "World probe bake (panel defaults)", "seconds": world_bake_s},
             {"what": "reference: one point's own 32^2 cube (render_probes, batched 24)", "seconds": ref_s}]
    costs += [{"what": f"source cube {f}^2 with depth (render + read back)", "seconds": main[f].render_s}
              for f in faces]
    costs.append({"what": "8 corner cubes 128^2 with depth", "seconds": sum(s.render_s for s in corner_src)})

    methods = [("reproj 128 point", [main[128]], {"footprint": False})]
    methods += [(f"reproj {f} splat", [main[f]], {}) for f in faces]
    methods += [("reproj 128 splat, 32^2 target", [main[128]], {"n": 32}),
                ("reproj 128 splat, holes at infinity", [main[128]], {"grow": 0}),
                ("reproj 128 splat, no z-test", [main[128]], {"ztest": False}),
                ("reproj 128 splat +8 corners, one z-test", [main[128]] + corner_src, {"merge": "ztest"}),
                ("reproj 128 splat +8 corners, nearest first", [main[128]] + corner_src, {})]
    rows, per_point, hybrid = [], {}, []
    for p in PLACES:
        pts, nrm, facing = data[p]
        want = refs[p]
        rows.append({"place": p, "method": "world", **errors(eval_irradiance(d_world, nrm), want, facing)})
        rows.append({"place": p, "method": "source cube, no parallax",
                     **errors(exact_irradiance(main[128].cube, nrm)[:, :3], want, facing)})
        own = Source(r, centre(p), 128)
        for name, srcs, kw in methods + [("reproj 128 splat + mesh centre, nearest first", [main[128], own], {})]:
            kw = dict(kw)
            n = kw.pop("n", target)
            got, holes, secs = reprojected(srcs, pts, nrm, n, **kw)
            per_point.setdefault((name, n), []).append(secs)
            rows.append({"place": p, "method": name, "hole": round(float(holes.mean()), 4),
                         **errors(got, want, facing)})
            print(p, name, {k: (round(v, 4) if isinstance(v, float) else v) for k, v in rows[-1].items()
                            if k not in ("place", "method")}, f"{secs * 1e3:.0f} ms/point", flush=True)
            if name == "reproj 128 splat":
                # the hybrid: real probes (the reference) at the points whose hole share is above a threshold
                for thr in (0.02, 0.05, 0.1, 0.2):
                    mix = np.where((holes > thr)[:, None], want, got)
                    hybrid.append({"place": p, "method": f"hybrid: probes where hole > {thr:g}",
                                   "hole": round(float((holes > thr).mean()), 4), **errors(mix, want, facing)})
    rows += hybrid
    for (name, n), secs in per_point.items():
        costs.append({"what": f"{name}: per point (numpy, {n}^2 target)", "seconds": float(np.mean(secs))})
    load = round((load0 + os.getloadavg()[0]) / 2, 2)
    for c in costs:
        c["ratio_to_reference_point"] = round(c["seconds"] / ref_s, 3)
        c["ratio_to_world_bake"] = round(c["seconds"] / world_bake_s, 3)
        c["load"] = load
    for row in rows:
        row["points"] = n_points
        row["load"] = load
    return rows, costs


REF_FACE_NOTE = "32^2, every splat"


def plot(rows: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [r for r in rows if not r["method"].startswith("hybrid") or r["method"].endswith("> 0.05")]
    places = list(dict.fromkeys(r["place"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
    w = 0.8 / len(methods)
    for k, m in enumerate(methods):
        xs = np.arange(len(places)) + (k - (len(methods) - 1) / 2) * w
        cell = [100 * max(abs(r[f"cell_{c}"] - 1) for c in "rgb") for p in places for r in rows
                if r["place"] == p and r["method"] == m]
        err = [100 * r["err_mean"] for p in places for r in rows if r["place"] == p and r["method"] == m]
        colour = plt.cm.tab20(k % 20)
        axes[0].bar(xs, cell, w, label=m, color=colour)
        axes[1].bar(xs, err, w, label=m, color=colour)
    for ax, title in zip(axes, ("camera-half mean, worst channel |ours / reference - 1|",
                                "per-point luminance error, mean")):
        ax.axhline(3, color="k", lw=0.8, ls=":")
        ax.set_xticks(np.arange(len(places)), places)
        ax.set_yscale("log")
        ax.set_ylabel("%")
        ax.set_title(title, fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.suptitle("One cube with depth, reprojected to each shading point, against each point's own rendered cube "
                 "(lavapipe; dotted: 3%)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def write_csv(rows: list[dict], costs: list[dict], path: str) -> None:
    stamp = datetime.date.today().isoformat()
    keys = ["date", "kind", "place", "method", "err_mean", "err_p95", "cell_r", "cell_g", "cell_b", "cell_ok", "hole",
            "points", "what", "seconds", "ratio_to_reference_point", "ratio_to_world_bake", "load"]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for r in rows:
            w.writerow({"date": stamp, "kind": "accuracy", **{k: (round(v, 5) if isinstance(v, float) else v)
                                                              for k, v in r.items()}})
        for c in costs:
            w.writerow({"date": stamp, "kind": "cost", **{k: (round(v, 5) if isinstance(v, float) else v)
                                                          for k, v in c.items()}})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=64)
    ap.add_argument("--target", type=int, default=64)
    ap.add_argument("--faces", default="64,128,256")
    ap.add_argument("--out-csv", default=os.path.join(REPO, "docs/bench/reprojection_lavapipe.csv"))
    ap.add_argument("--png", default=os.path.join(REPO, "docs/img/reprojection_study.png"))
    a = ap.parse_args()
    faces = [int(f) for f in a.faces.split(",")]
    if 128 not in faces:
        faces.insert(0, 128)
    faces = sorted(faces, key=lambda f: (f != 128, f))  # 128 first: the main source
    scene = read_scene(os.path.join(REPO, "samples/room.ply"))
    r = SplatRenderer(scene)
    rows, costs = study(r, scene, a.points, a.target, faces)
    print(f"{'place':8} {'method':34} {'err_mean':>8} {'err_p95':>8} {'R':>6} {'G':>6} {'B':>6} ok   hole")
    for x in rows:
        print(f"{x['place']:8} {x['method']:34} {x['err_mean']:8.4f} {x['err_p95']:8.4f} {x['cell_r']:6.3f} "
              f"{x['cell_g']:6.3f} {x['cell_b']:6.3f} {'yes' if x['cell_ok'] else 'no ':4} {x.get('hole', '')}")
    for c in costs:
        print(f"{c['what']:70} {c['seconds'] * 1e3:9.1f} ms  x{c['ratio_to_reference_point']:.2f} of a reference "
              f"point, x{c['ratio_to_world_bake']:.2f} of the World bake (load {c['load']})")
    write_csv(rows, costs, a.out_csv)
    plot(rows, a.png)
    print("wrote", a.out_csv, a.png)


if __name__ == "__main__":
    main()
