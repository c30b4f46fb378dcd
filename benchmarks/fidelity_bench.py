"""Fidelity of a capture in a final render (issue 36, item 4): our camera path against gsplat 1.5.3's classic
rasterization, eight views around each real capture.

Ours is what an F12 render draws (blender/render/splats.py render_layers): ``ViewBatch.camera`` with the frame's
lens shift, ``SplatRenderer(scene, near=clip_start).render_camera(batch, cut=...)`` (render(cut=...) where the core
has no render_camera) with the cut at the far clip where no mesh stands (every pixel here: FRONT is the frame).
The peer is 3DGS's look as its viewers draw it: gsplat's ``rasterization(..., rasterize_mode="classic",
packed=True, eps2d=0.3)`` with 3DGS's own projection (EWA, the clamped Jacobian), the same camera (OpenCV view
matrix, K with the shifted principal point), the same near and far planes. The colour rule is off (each scene's
colour space set to "linear": colour = max(SH(d) + 0.5, 0), what gsplat computes), so both images are the values
the capture was trained to show.

Views (``camera_views``): around the capture's centre (the median of its splats), looking at it, from outside its
dense core (R: the distance from the centre within which 80% of the splats lie), at 1920x1080 and 60° across by
default: two views at 2.4 R (the capture in the frame, its long parts crossing the image edge), two at 1.7 R (one
with a lens shift), two at 1.25 R (the capture fills the frame: splats at every edge), two at 1.05 R (the outer
splats near the camera, one with a lens shift). Azimuths 45° apart about the capture's up axis, elevations -10° to
35°. The first view is also drawn through a render border (a window of the frame: its pixels must be the frame's)
and without the depth cut (the same image).

Per view: PSNR of RGB (premultiplied over black, both clipped to [0, 1], peak 1) and of alpha, mean and largest
absolute difference, the share of pixels more than 1% off. Per capture: the median and the worst view, and for the
worst view which splats differ: the pixels with the largest differences, as many as hold half the squared
difference (TOP_SHARE), each classified: ``order`` where 3DGS's own splats blended in our order (by distance from
the camera, not by view depth: ClassicNumpy(order="distance")) come at least twice nearer to our pixel (it is the
order, not the footprints); else by the splat that dominates the pixel in 3DGS's image (the largest blending weight):
``near`` (its depth under NEAR_FRAC of the view's median splat depth), ``edge`` (its projected centre within
EDGE_FRAC of the frame's width of the image border, or outside the frame), ``needle`` (longest axis over the middle
one >= NEEDLE_RATIO), ``other``, ``ours-only`` (no splat of 3DGS's image covers the pixel). Their shares of the
squared difference, and the PSNR of ours against 3DGS sorted by distance, go to ``--worst-csv``, the 20 splats
holding most of it to ``--splats-csv``, a picture of the worst view (ours, 3DGS, the difference x10) to
``--png-dir``.

``ClassicNumpy`` is gsplat 1.5.3's classic path ported to numpy (csrc/ProjectionEWA3DGSPacked.cu, Utils.cuh
persp_proj and add_blur, IntersectTile.cu, RasterizeToPixels3DGSFwd.cu: the same culling, opacity-aware radius,
16-px tile intersection, depth order and alpha rules). It stands in for gsplat where CUDA is missing (``--peer
numpy``: lavapipe, the tests) and finds the dominant splats; ``--check-port WxH`` measures it against gsplat on the
GPU machine (rows with peer "numpy-port" in the CSV: it is a faithful stand-in where their PSNR is far above 38 dB).

  python benchmarks/fidelity_bench.py [CAPTURE.ply[@UP] ...] [--size 1920x1080] [--fov 60] [--peer auto|gsplat|numpy]
         [--csv out/bench/fidelity.csv] [--worst-csv ...] [--splats-csv ...] [--png-dir out/bench]
         [--check-port 320x180] [--what-if-all] [--deadline SECONDS]

Captures: tests/data/guitar.compressed.ply (up -Y: a Y-down capture) and samples/room.ply (up +Z), plus any path
on the command line (``path@+z`` names its up axis; default -y, the COLMAP convention of trained captures).
Target (issue 36): every view of every real capture >= 38 dB on the GPU machine.
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import statistics
import sys
import time
from dataclasses import dataclass

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

from bench_common import append_csv  # noqa: E402

CAPTURES = {"guitar": (os.path.join(ROOT, "tests", "data", "guitar.compressed.ply"), "-y"),
            "room": (os.path.join(ROOT, "samples", "room.ply"), "+z")}
# (azimuth deg, elevation deg, distance in dense-core radii, lens shift (x, y) in Blender's units: the frame's
# centre at distance 1, times 2 tan of half the horizontal angle)
VIEWS = ((0, 15, 2.4, (0.0, 0.0)), (45, -10, 2.4, (0.0, 0.0)), (90, 30, 1.7, (0.0, 0.0)),
         (135, 5, 1.7, (0.15, -0.1)), (180, 15, 1.25, (0.0, 0.0)), (225, -10, 1.25, (0.0, 0.0)),
         (270, 35, 1.05, (0.0, 0.0)), (315, 0, 1.05, (-0.1, 0.08)))
CORE_SHARE = 0.8  # the dense core: the sphere about the centre holding this share of the splats
TARGET_DB = 38.0
NEAR_FRAC, EDGE_FRAC, NEEDLE_RATIO = 0.5, 0.05, 8.0
TOP_SHARE = 0.5  # the worst view's pixels classified: those with the largest differences holding this share
T0 = time.perf_counter()


def log(*a) -> None:
    print(f"[{time.perf_counter() - T0:7.1f}s]", *a, flush=True)


# ---- captures and cameras ----

def parse_capture(spec: str) -> tuple[str, str, str]:
    """(name, path, up) of a CAPTURES key or ``path[@up]``."""
    if spec in CAPTURES:
        return (spec, *CAPTURES[spec])
    path, _, up = spec.partition("@")
    return os.path.splitext(os.path.basename(path.rstrip("/")))[0].split(".")[0], path, up or "-y"


def up_vector(up: str) -> np.ndarray:
    axis = {"x": 0, "y": 1, "z": 2}[up[-1].lower()]
    v = np.zeros(3)
    v[axis] = -1.0 if up.startswith("-") else 1.0
    return v


def load_capture(path: str):
    """The capture with the colour rule off (its SH read as linear values, as gsplat reads them)."""
    from gs_ibl_addon.core.formats import read_scene
    scene = read_scene(path)
    scene.colour_space = "linear"
    return scene


def capture_frame(scene) -> tuple[np.ndarray, float]:
    """(centre, dense-core radius): the median of the splats and the distance holding CORE_SHARE of them."""
    c = np.median(scene.positions.astype(np.float64), 0)
    r = float(np.quantile(np.linalg.norm(scene.positions - c, axis=1), CORE_SHARE))
    return c, r


@dataclass(frozen=True)
class CameraView:
    """One camera as Blender gives it to a final render (blender/render/camera.py FrameCamera)."""
    name: str
    matrix: np.ndarray  # camera to world, Blender's convention (looks down -Z, +Y up)
    tan_x: float
    tan_y: float
    width: int
    height: int
    shift: tuple[float, float]  # (cx, cy) in tan units at distance 1, right and up (ViewBatch.camera's shift)
    azimuth: float = 0.0
    elevation: float = 0.0
    distance: float = 0.0
    factor: float = 0.0


def look_at(position, target, up) -> np.ndarray:
    """Blender's camera-to-world matrix of a camera at ``position`` looking at ``target``."""
    f = np.asarray(target, np.float64) - position
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-6:
        r = np.cross(f, [1.0, 0.0, 0.0] if abs(f[0]) < 0.9 else [0.0, 1.0, 0.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = r, u, -f, position
    return m


def camera_views(scene, up: str, width: int, height: int, fov_deg: float = 60.0) -> list[CameraView]:
    """The eight views of VIEWS around ``scene`` (module docstring)."""
    centre, radius = capture_frame(scene)
    u = up_vector(up)
    a = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    tx = math.tan(math.radians(fov_deg) / 2)
    ty = tx * height / width
    out = []
    for i, (az, el, k, (sx, sy)) in enumerate(VIEWS):
        azr, elr = math.radians(az), math.radians(el)
        d = (math.cos(azr) * e1 + math.sin(azr) * e2) * math.cos(elr) + u * math.sin(elr)
        pos = centre + k * radius * d
        # Blender's shift is in units of the fitted sensor side (width here): cx = shift * 2 tan_x
        out.append(CameraView(f"v{i}", look_at(pos, centre, u), tx, ty, width, height,
                              (2 * tx * sx, 2 * tx * sy), az, el, k * radius, k))
    return out


def our_batch(cv: CameraView, window=None):
    from gs_ibl_addon.core.render.views import ViewBatch
    return ViewBatch.camera(cv.matrix, cv.tan_x, cv.tan_y, cv.width, cv.height, shift=cv.shift, window=window)


def opencv_camera(cv: CameraView) -> tuple[np.ndarray, np.ndarray]:
    """(world-to-camera 4x4, K 3x3) of ``cv`` in OpenCV's convention (x right, y down, z forward), gsplat's input:
    the same rays through the same pixel centres as our_batch(cv) (a shift moves the principal point)."""
    v = our_batch(cv).views[0]
    rot = np.stack([v.right, v.down, v.forward])
    vm = np.eye(4)
    vm[:3, :3], vm[:3, 3] = rot, -rot @ cv.matrix[:3, 3]
    fx, fy = cv.width / (2 * cv.tan_x), cv.height / (2 * cv.tan_y)
    k = np.array([[fx, 0.0, cv.width / 2 - v.cx * fx], [0.0, fy, cv.height / 2 - v.cy * fy], [0.0, 0.0, 1.0]])
    return vm, k


# ---- the renderers ----

class Ours:
    """The F12 path: ViewBatch.camera, SplatRenderer(near=clip_start), render(cut=far clip): its FRONT layer."""
    name = "gs-ibl"

    def __init__(self, scene, near: float, far: float, ctx=None) -> None:
        from gs_ibl_addon.core.render.renderer import SplatRenderer
        self.r = SplatRenderer(scene, ctx, near=near)
        self.far = far

    def render(self, cv: CameraView, window=None, cut: bool = True) -> np.ndarray:
        batch = our_batch(cv, window)
        v = batch.views[0]
        c = np.full((v.height, v.width), self.far, np.float32) if cut else None
        if hasattr(self.r, "render_camera"):  # what F12 calls (blender/render/splats.py render_layers)
            return self.r.render_camera(batch, cut=c, depth=False, timestamps=False).front
        return self.r.render(batch, cut=c).images[0]

    def close(self) -> None:
        self.r.close()


class GsplatCuda:
    """gsplat 1.5.3's rasterization, classic mode (3DGS's look), on CUDA."""
    name = "gsplat 1.5.3 classic"

    def __init__(self, scene, near: float, far: float) -> None:
        import gsplat
        import torch
        self.torch, self.raster = torch, gsplat.rasterization
        f = lambda a: torch.from_numpy(np.ascontiguousarray(a, np.float32)).cuda()  # noqa: E731
        self.t = (f(scene.positions), f(scene.rotations), f(scene.scales), f(scene.opacities), f(scene.sh))
        self.deg = int(round(math.sqrt(scene.sh.shape[1]))) - 1
        self.near, self.far = near, far

    def render(self, cv: CameraView) -> np.ndarray:
        vm, k = opencv_camera(cv)
        tt = lambda a: self.torch.tensor(np.array(a)[None], dtype=self.torch.float32, device="cuda")  # noqa: E731
        colors, alphas, _ = self.raster(*self.t, tt(vm), tt(k), cv.width, cv.height, sh_degree=self.deg,
                                        near_plane=self.near, far_plane=self.far, rasterize_mode="classic",
                                        packed=True)
        return np.concatenate([colors[0].float().cpu().numpy(), alphas[0].float().cpu().numpy()], -1)


ALPHA_THRESHOLD = 1.0 / 255.0


class ClassicNumpy:
    """gsplat 1.5.3's classic rasterization in numpy (module docstring), float32 where gsplat is; ``render`` also
    gives each pixel's dominant splat (largest blending weight; -1: none)."""
    name = "numpy port of gsplat classic"

    def __init__(self, scene, near: float, far: float, tile: int = 16, eps2d: float = 0.3,
                 alpha_max: float = 0.999, order: str = "depth") -> None:
        from gs_ibl_addon.core.scene import quat_to_matrix
        q = scene.rotations.astype(np.float64)
        rot = quat_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))  # gsplat normalises its quaternions
        m = rot * scene.scales.astype(np.float64)[:, None, :]
        self.cov = np.einsum("nij,nkj->nik", m, m)
        self.scene, self.near, self.far, self.tile, self.eps2d = scene, near, far, tile, eps2d
        self.alpha_max, self.order = alpha_max, order  # what-ifs (diagnose): our clamp, our order by distance

    def project(self, cv: CameraView) -> dict:
        """ProjectionEWA3DGSPacked.cu for one camera: the splats kept, their 2D means, depths, conics, radii."""
        from gs_ibl_addon.core.sh import eval_sh_color
        vm, k = opencv_camera(cv)
        w, h = cv.width, cv.height
        mu = self.scene.positions.astype(np.float64)
        mc = mu @ vm[:3, :3].T + vm[:3, 3]
        x, y, z = mc.T
        keep = (z >= self.near) & (z <= self.far)
        ids = np.flatnonzero(keep)
        x, y, z = x[ids], y[ids], z[ids]
        r = vm[:3, :3]
        cc = np.einsum("ij,njk,lk->nil", r, self.cov[ids], r)
        fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
        tfx, tfy = 0.5 * w / fx, 0.5 * h / fy
        lxp, lxn = (w - cx) / fx + 0.3 * tfx, cx / fx + 0.3 * tfx
        lyp, lyn = (h - cy) / fy + 0.3 * tfy, cy / fy + 0.3 * tfy
        tx = z * np.minimum(lxp, np.maximum(-lxn, x / z))
        ty = z * np.minimum(lyp, np.maximum(-lyn, y / z))
        j = np.zeros((len(ids), 2, 3))
        j[:, 0, 0], j[:, 1, 1] = fx / z, fy / z
        j[:, 0, 2], j[:, 1, 2] = -fx * tx / z ** 2, -fy * ty / z ** 2
        c2 = np.einsum("nij,njk,nlk->nil", j, cc, j)
        mean = np.stack([fx * x / z + cx, fy * y / z + cy], 1)
        c2[:, 0, 0] += self.eps2d
        c2[:, 1, 1] += self.eps2d
        det = c2[:, 0, 0] * c2[:, 1, 1] - c2[:, 0, 1] * c2[:, 1, 0]
        op = self.scene.opacities[ids].astype(np.float64)
        ok = (det > 0) & (op >= ALPHA_THRESHOLD)
        ext = np.minimum(3.33, np.sqrt(2.0 * np.log(np.maximum(op, ALPHA_THRESHOLD) / ALPHA_THRESHOLD)))
        rx = np.ceil(ext * np.sqrt(np.maximum(c2[:, 0, 0], 0)))
        ry = np.ceil(ext * np.sqrt(np.maximum(c2[:, 1, 1], 0)))
        ok &= ~((rx <= 0) & (ry <= 0))
        ok &= ~((mean[:, 0] + rx <= 0) | (mean[:, 0] - rx >= w) | (mean[:, 1] + ry <= 0) | (mean[:, 1] - ry >= h))
        sel = np.flatnonzero(ok)
        ids, det = ids[sel], det[sel]
        c2 = c2[sel]
        conic = np.stack([c2[:, 1, 1] / det, -c2[:, 0, 1] / det, c2[:, 0, 0] / det], 1)
        d = mu[ids] - cv.matrix[:3, 3]
        color = eval_sh_color(self.scene.sh[ids], d / np.linalg.norm(d, axis=1, keepdims=True))
        return {"ids": ids, "mean": mean[sel], "depth": z[sel], "conic": conic, "opacity": op[sel],
                "rx": rx[sel], "ry": ry[sel], "color": color}

    def render(self, cv: CameraView, dominant: bool = False):
        """(H, W, 4) float32 premultiplied RGB and alpha; with ``dominant`` also (H, W) int64 splat ids."""
        p = self.project(cv)
        w, h, ts = cv.width, cv.height, self.tile
        tw, th = -(-w // ts), -(-h // ts)
        mx, my = p["mean"][:, 0], p["mean"][:, 1]
        # IntersectTile.cu: the tiles of each splat's radius box (float -> uint32 saturates at 0 on the GPU)
        x0 = np.clip(np.floor((mx - p["rx"]) / ts), 0, tw).astype(np.int64)
        x1 = np.clip(np.ceil((mx + p["rx"]) / ts), 0, tw).astype(np.int64)
        y0 = np.clip(np.floor((my - p["ry"]) / ts), 0, th).astype(np.int64)
        y1 = np.clip(np.ceil((my + p["ry"]) / ts), 0, th).astype(np.int64)
        cnt = (x1 - x0) * (y1 - y0)
        g = np.repeat(np.arange(len(cnt)), cnt)
        local = np.arange(len(g)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        wd = (x1 - x0)[g]
        tile = (y0[g] + local // np.maximum(wd, 1)) * tw + x0[g] + local % np.maximum(wd, 1)
        # one stable radix sort of (tile, float32 depth bits) keys: ties keep the splats' order
        key = p["depth"] if self.order == "depth" else np.linalg.norm(
            self.scene.positions[p["ids"]].astype(np.float64) - cv.matrix[:3, 3], axis=1)
        order = np.lexsort((g, key.astype(np.float32)[g], tile))
        g, tile = g[order], tile[order]
        bounds = np.searchsorted(tile, np.arange(tw * th + 1))
        f32 = np.float32
        mean, conic = p["mean"].astype(f32), p["conic"].astype(f32)
        op, col = p["opacity"].astype(f32), p["color"].astype(f32)
        img = np.zeros((h, w, 4), f32)
        dom = np.full((h, w), -1, np.int64) if dominant else None
        for t in np.flatnonzero(np.diff(bounds)):
            ty_, tx_ = divmod(int(t), tw)
            ys, xs = np.mgrid[ty_ * ts:min(ty_ * ts + ts, h), tx_ * ts:min(tx_ * ts + ts, w)]
            px, py = xs.ravel().astype(f32) + f32(0.5), ys.ravel().astype(f32) + f32(0.5)
            n_px = len(px)
            trans = np.ones(n_px, f32)
            done = np.zeros(n_px, bool)
            acc = np.zeros((n_px, 3), f32)
            best_w, best = np.zeros(n_px, f32), np.full(n_px, -1, np.int64)
            s, e = int(bounds[t]), int(bounds[t + 1])
            step = 64
            while s < e and not done.all():
                gg = g[s:min(s + step, e)]
                s += len(gg)
                step = min(step * 2, 1024)
                dx = mean[gg, 0][None] - px[:, None]
                dy = mean[gg, 1][None] - py[:, None]
                sig = f32(0.5) * (conic[gg, 0][None] * dx * dx + conic[gg, 2][None] * dy * dy) \
                    + conic[gg, 1][None] * dx * dy
                alpha = np.minimum(f32(self.alpha_max), op[gg][None] * np.exp(-sig))
                alpha[(sig < 0) | (alpha < ALPHA_THRESHOLD)] = 0
                alpha[done] = 0
                nxt = trans[:, None] * np.cumprod(f32(1) - alpha, axis=1)
                stop = nxt <= f32(1e-4)
                hit = stop.any(1)
                first = np.where(hit, stop.argmax(1), alpha.shape[1])
                before = np.concatenate([trans[:, None], nxt[:, :-1]], 1)
                wgt = alpha * before * (np.arange(alpha.shape[1])[None] < first[:, None])
                acc += wgt @ col[gg]
                if dominant:
                    k = wgt.argmax(1)
                    wk = wgt[np.arange(n_px), k]
                    better = wk > best_w
                    best_w[better], best[better] = wk[better], p["ids"][gg[k[better]]]
                last = np.where(first > 0, nxt[np.arange(n_px), np.maximum(first - 1, 0)], trans)
                trans = np.where(done, trans, np.where(hit, last, nxt[:, -1]))
                done |= hit
            img[ys.ravel(), xs.ravel(), :3] = acc
            img[ys.ravel(), xs.ravel(), 3] = 1 - trans
            if dominant:
                dom[ys.ravel(), xs.ravel()] = best
        return (img, dom) if dominant else img


# ---- comparison ----

def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((np.clip(a, 0, 1).astype(np.float64) - np.clip(b, 0, 1)) ** 2))
    return 99.0 if mse <= 1e-10 else min(99.0, 10 * math.log10(1.0 / mse))


def compare(ours: np.ndarray, peer: np.ndarray) -> dict:
    d = np.abs(np.clip(ours[..., :3], 0, 1) - np.clip(peer[..., :3], 0, 1)).max(-1)
    return {"psnr": round(psnr(ours[..., :3], peer[..., :3]), 3),
            "psnr_alpha": round(psnr(ours[..., 3], peer[..., 3]), 3),
            "mean_abs": round(float(d.mean()), 6), "max_abs": round(float(d.max()), 5),
            "px_over_1pct": round(float((d > 0.01).mean()), 6),
            "coverage_ours": round(float(ours[..., 3].mean()), 4),
            "coverage_peer": round(float(peer[..., 3].mean()), 4)}


def splat_traits(scene, port: ClassicNumpy, cv: CameraView, ids: np.ndarray) -> dict:
    """Depth (view z), distance of the projected centre to the frame's border in pixels (negative: outside) and
    anisotropy (longest axis over the middle one) of splats ``ids``."""
    vm, k = opencv_camera(cv)
    mc = scene.positions[ids].astype(np.float64) @ vm[:3, :3].T + vm[:3, 3]
    z = mc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = k[0, 0] * mc[:, 0] / z + k[0, 2]
        v = k[1, 1] * mc[:, 1] / z + k[1, 2]
    edge = np.minimum.reduce([u, cv.width - u, v, cv.height - v])
    edge = np.where(z > 0, edge, -np.inf)
    s = np.sort(scene.scales[ids].astype(np.float64), 1)
    return {"depth": z, "edge_px": edge, "anisotropy": s[:, 2] / np.maximum(s[:, 1], 1e-12), "scale": s[:, 2]}


CLASSES = ("order", "near", "edge", "needle", "other", "ours-only")


def diagnose(scene, port: "ClassicNumpy", cv: CameraView, ours: np.ndarray,
             ref: np.ndarray) -> tuple[list, list, float]:
    """(class rows, splat rows, PSNR of ours against 3DGS sorted by distance) for the pixels holding half the
    squared difference (module docstring)."""
    _, dom = port.render(cv, dominant=True)
    what_if = ClassicNumpy(scene, port.near, port.far, order="distance").render(cv)
    clip = lambda x: np.clip(x[..., :3], 0, 1).astype(np.float64)  # noqa: E731
    sq = ((clip(ours) - clip(ref)) ** 2).sum(-1).ravel()
    sq_if = ((clip(ours) - clip(what_if)) ** 2).sum(-1).ravel()
    total = float(sq.sum()) or 1.0
    by_err = np.argsort(sq)[::-1]
    n_top = int(np.searchsorted(np.cumsum(sq[by_err]), TOP_SHARE * total)) + 1
    top = by_err[:min(n_top, sq.size)]
    ids, err = dom.ravel()[top], sq[top]
    seen = ids >= 0
    tr = splat_traits(scene, port, cv, np.maximum(ids, 0))
    drawn = np.unique(dom[dom >= 0])
    median_depth = float(np.median(splat_traits(scene, port, cv, drawn)["depth"])) if drawn.size else 1.0
    cls = np.full(len(ids), "other", object)
    cls[tr["anisotropy"] >= NEEDLE_RATIO] = "needle"
    cls[tr["edge_px"] < EDGE_FRAC * cv.width] = "edge"
    cls[tr["depth"] < NEAR_FRAC * median_depth] = "near"
    cls[~seen] = "ours-only"
    cls[sq_if[top] <= 0.5 * err] = "order"  # 3DGS's own splats in our order: at least twice nearer to ours
    rows = []
    for c in CLASSES:
        m = cls == c
        rows.append({"class": c, "pixels": int(m.sum()), "share_of_top_pixels": round(float(m.mean()), 4),
                     "share_of_sq_error": round(float(err[m].sum() / total), 4)})
    rows.append({"class": "top pixels (all)", "pixels": len(top), "share_of_top_pixels": 1.0,
                 "share_of_sq_error": round(float(err.sum() / total), 4)})
    splats = []
    if seen.any():
        uid, inv = np.unique(ids[seen], return_inverse=True)
        e = np.bincount(inv, weights=err[seen])
        px = np.bincount(inv)
        main = {}  # each splat's class: that of most of its error
        for c in CLASSES:
            m = cls[seen] == c
            main[c] = np.bincount(inv[m], weights=err[seen][m], minlength=len(uid))
        tu = splat_traits(scene, port, cv, uid)
        for rank, j in enumerate(np.argsort(e)[::-1][:20]):
            splats.append({"rank": rank + 1, "splat": int(uid[j]), "class": max(CLASSES, key=lambda c: main[c][j]),
                           "pixels": int(px[j]), "share_of_sq_error": round(float(e[j] / total), 4),
                           "depth": round(float(tu["depth"][j]), 4), "edge_px": round(float(tu["edge_px"][j]), 1),
                           "anisotropy": round(float(tu["anisotropy"][j]), 2),
                           "scale": round(float(tu["scale"][j]), 5),
                           "opacity": round(float(scene.opacities[uid[j]]), 3)})
    return rows, splats, round(psnr(ours[..., :3], what_if[..., :3]), 3)


def save_triptych(path: str, title: str, ours: np.ndarray, ref: np.ndarray) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    step = max(1, ours.shape[1] // 960)
    a, b = np.clip(ours[::step, ::step, :3], 0, 1), np.clip(ref[::step, ::step, :3], 0, 1)
    d = np.clip(np.abs(a - b).max(-1) * 10, 0, 1)
    fig, axes = plt.subplots(1, 3, figsize=(15, 15 * a.shape[0] / a.shape[1] / 3 + 0.6))
    for ax, im, t in zip(axes, (a, b, d), ("gs-ibl (F12 camera path)", "3DGS classic", "|difference| x 10")):
        ax.imshow(im, cmap="magma" if im.ndim == 2 else None, vmin=0, vmax=1)
        ax.set_title(t, fontsize=9)
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def make_peer(kind: str, scene, near: float, far: float):
    if kind in ("auto", "gsplat"):
        try:
            from peer_bench import load_gsplat
            load_gsplat()
            return GsplatCuda(scene, near, far)
        except Exception as e:  # noqa: BLE001 - no torch / CUDA / gsplat here
            if kind == "gsplat":
                raise
            log(f"gsplat unavailable ({type(e).__name__}: {e}); the numpy port stands in")
    return ClassicNumpy(scene, near, far)


def parse_size(s: str) -> tuple[int, int]:
    w, h = (int(x) for x in s.lower().split("x"))
    return w, h


def run(args) -> list[dict]:
    from bench_common import gpu_clock, hold_gpu_clock
    from gs_ibl_addon.core.vk import get_context
    hold = hold_gpu_clock()  # noqa: F841 - keeps the CUDA context (and the SM clock) for the run
    ctx = get_context()
    width, height = parse_size(args.size)
    date = datetime.date.today().isoformat()
    deadline = T0 + args.deadline if args.deadline else None
    summaries = []
    specs = [s for s in args.captures.split(",") if s] + list(args.paths)
    for spec in specs:
        name, path, up = parse_capture(spec)
        if deadline and time.perf_counter() > deadline:
            log(f"past --deadline {args.deadline:.0f} s: {name} left out")
            continue
        scene = load_capture(path)
        views = camera_views(scene, up, width, height, args.fov)
        centre, radius = capture_frame(scene)
        peer = make_peer(args.peer, scene, args.near, args.far)
        ours = Ours(scene, args.near, args.far, ctx)
        log(f"{name}: {scene.count:,} splats, centre {np.round(centre, 3).tolist()}, core radius {radius:.3f}, "
            f"peer: {peer.name}")
        rows, images = [], {}
        for cv in views:
            t = time.perf_counter()
            a = ours.render(cv)
            t_ours = time.perf_counter() - t
            t = time.perf_counter()
            b = peer.render(cv)
            t_peer = time.perf_counter() - t
            row = {"device": ctx.device_name, "peer": peer.name, "date": date, "capture": name, "splats": scene.count,
                   "view": cv.name, "azimuth": cv.azimuth, "elevation": cv.elevation,
                   "distance": round(cv.distance, 4), "core_radii": cv.factor, "shift_x": round(cv.shift[0], 4),
                   "shift_y": round(cv.shift[1], 4), "width": width, "height": height, "fov": args.fov,
                   "near": args.near, **compare(a, b), "psnr_if_distance_order": "",
                   "window_max_diff": "", "nocut_max_diff": "",
                   "sm_mhz": gpu_clock(), "ours_s": round(t_ours, 3), "peer_s": round(t_peer, 3)}
            if args.what_if_all:  # 3DGS's splats blended in our order, by distance (diagnose's what-if)
                w = ClassicNumpy(scene, args.near, args.far, order="distance").render(cv)
                row["psnr_if_distance_order"] = round(psnr(a[..., :3], w[..., :3]), 3)
            if cv is views[0]:  # a render border's window and the frame without the cut: the same pixels
                x0, y0, x1, y1 = width // 4, height // 3, (3 * width) // 4, (5 * height) // 6
                win = ours.render(cv, window=(x0, y0, x1, y1))
                row["window_max_diff"] = float(np.abs(win - a[y0:y1, x0:x1]).max())
                row["nocut_max_diff"] = float(np.abs(ours.render(cv, cut=False) - a).max())
            rows.append(row)
            images[cv.name] = (a, b)
            log(f"  {name} {cv.name} az {cv.azimuth:3.0f} el {cv.elevation:3.0f} {cv.factor:.2f} R shift "
                f"{cv.shift[0]:+.3f},{cv.shift[1]:+.3f}: PSNR {row['psnr']:.2f} dB (alpha {row['psnr_alpha']:.2f}), "
                f"max {row['max_abs']:.3f}, >1%: {100 * row['px_over_1pct']:.2f}%"
                + (f", {row['psnr_if_distance_order']:.2f} dB if 3DGS sorted by distance" if args.what_if_all else "")
                + f" | ours {t_ours:.2f} s, "
                f"peer {t_peer:.2f} s")
            append_csv(args.csv, [row])
        ps = [r["psnr"] for r in rows]
        worst = min(rows, key=lambda r: r["psnr"])
        summary = {"capture": name, "splats": scene.count, "views": len(rows), "median_psnr": statistics.median(ps),
                   "worst_psnr": worst["psnr"], "worst_view": worst["view"],
                   "below_target": sum(p < TARGET_DB for p in ps), "peer": peer.name,
                   "window_max_diff": rows[0]["window_max_diff"], "nocut_max_diff": rows[0]["nocut_max_diff"]}
        a, b = images[worst["view"]]
        cv = next(v for v in views if v.name == worst["view"])
        if args.diagnose and not (deadline and time.perf_counter() > deadline):
            t = time.perf_counter()
            port = peer if isinstance(peer, ClassicNumpy) else ClassicNumpy(scene, args.near, args.far)
            cls, splats, if_order = diagnose(scene, port, cv, a, b)
            base = {"capture": name, "view": cv.name, "psnr": worst["psnr"],
                    "psnr_if_3dgs_sorted_by_distance": if_order}
            append_csv(args.worst_csv, [{**base, **r} for r in cls])
            append_csv(args.splats_csv, [{**base, **r} for r in splats])
            summary["classes"] = {r["class"]: r["share_of_sq_error"] for r in cls}
            summary["psnr_if_distance_order"] = if_order
            share = cls[-1]["pixels"] / (width * height)
            log(f"  worst view {cv.name}: {cls[-1]['pixels']:,} pixels ({100 * share:.2f}%) "
                f"hold half the squared difference; by class (share of all of it): "
                + ", ".join(f"{r['class']} {100 * r['share_of_sq_error']:.1f}%" for r in cls[:-1])
                + f"; 3DGS's splats in our order (by distance): {if_order:.2f} dB ({time.perf_counter() - t:.1f} s)")
            for sp in splats[:5]:
                log(f"    splat {sp['splat']}: {sp['class']}, {100 * sp['share_of_sq_error']:.1f}% of the error, depth "
                    f"{sp['depth']}, {sp['edge_px']} px from the edge, anisotropy {sp['anisotropy']}, "
                    f"scale {sp['scale']}")
        if args.png_dir:
            os.makedirs(args.png_dir, exist_ok=True)
            save_triptych(os.path.join(args.png_dir, f"fidelity_{name}_worst.png"),
                          f"{name}, view {cv.name} ({worst['psnr']:.1f} dB against {peer.name}), {width}x{height}",
                          a, b)
        if args.check_port and not isinstance(peer, ClassicNumpy) and not (deadline and time.perf_counter() > deadline):
            check_port(scene, name, up, args, ctx.device_name, date, peer)
        ours.close()
        del peer
        summaries.append(summary)
    print_table(summaries)
    return summaries


def check_port(scene, name, up, args, device, date, peer) -> None:
    """The numpy port against gsplat on every view at a small size (rows of peer "numpy-port")."""
    w, h = parse_size(args.check_port)
    port = ClassicNumpy(scene, args.near, args.far)
    ps = []
    for cv in camera_views(scene, up, w, h, args.fov):
        a, b = port.render(cv), peer.render(cv)
        row = {"device": device, "peer": "numpy-port", "date": date, "capture": name, "splats": scene.count,
               "view": cv.name, "azimuth": cv.azimuth, "elevation": cv.elevation, "distance": round(cv.distance, 4),
               "core_radii": cv.factor, "shift_x": round(cv.shift[0], 4), "shift_y": round(cv.shift[1], 4),
               "width": w, "height": h, "fov": args.fov, "near": args.near, **compare(a, b),
               "psnr_if_distance_order": "", "window_max_diff": "", "nocut_max_diff": "", "sm_mhz": "", "ours_s": "",
               "peer_s": ""}
        append_csv(args.csv, [row])
        ps.append(row["psnr"])
    log(f"  numpy port against gsplat at {w}x{h}: PSNR min {min(ps):.1f}, median {statistics.median(ps):.1f} dB")


def print_table(summaries: list[dict]) -> None:
    print(f"\n{'capture':<12}{'splats':>9}{'views':>6}{'median dB':>11}{'worst dB':>10}{'worst':>7}{'<38':>5}"
          f"{'dist.order':>11}  {'worst view: half its squared error, by class':<52} peer")
    for s in summaries:
        cl = s.get("classes", {})
        cls = ", ".join(f"{k} {100 * v:.0f}%" for k, v in cl.items() if k in CLASSES and v >= 0.005) or "-"
        print(f"{s['capture']:<12}{s['splats']:>9,}{s['views']:>6}{s['median_psnr']:>11.2f}{s['worst_psnr']:>10.2f}"
              f"{s['worst_view']:>7}{s['below_target']:>5}{s.get('psnr_if_distance_order', ''):>11}  {cls:<52} "
              f"{s['peer']}")
    print(f"target: every view >= {TARGET_DB:.0f} dB; window/no-cut checks (largest difference, want 0): "
          + ", ".join(f"{s['capture']} {s['window_max_diff']}/{s['nocut_max_diff']}" for s in summaries))


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("paths", nargs="*", help="more captures: PATH[@UP] (UP: +x, -y, +z, ...; default -y)")
    ap.add_argument("--captures", default="guitar,room", help="of " + ", ".join(CAPTURES) + " (comma-separated; "
                    "empty: only the paths)")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--fov", type=float, default=60.0, help="horizontal field of view, degrees")
    ap.add_argument("--near", type=float, default=0.1, help="clip start (Blender's default camera's)")
    ap.add_argument("--far", type=float, default=1000.0, help="clip end: the depth cut where no mesh stands")
    ap.add_argument("--peer", choices=("auto", "gsplat", "numpy"), default="auto")
    ap.add_argument("--check-port", default="", help="WxH: also the numpy port against gsplat at this size")
    ap.add_argument("--no-diagnose", dest="diagnose", action="store_false",
                    help="skip the worst view's classification (a numpy render of it)")
    ap.add_argument("--what-if-all", action="store_true", help="every view also against 3DGS's splats blended in "
                    "our order (by distance; a numpy render of each view): column psnr_if_distance_order")
    ap.add_argument("--deadline", type=float, default=0.0, help="seconds: captures not begun by then are left out")
    ap.add_argument("--csv", default=os.path.join(ROOT, "out", "bench", "fidelity.csv"))
    ap.add_argument("--worst-csv", default=os.path.join(ROOT, "out", "bench", "fidelity_worst.csv"))
    ap.add_argument("--splats-csv", default=os.path.join(ROOT, "out", "bench", "fidelity_splats.csv"))
    ap.add_argument("--png-dir", default="", help="a picture of each capture's worst view goes here")
    return run(ap.parse_args(argv))


if __name__ == "__main__":
    main()
