"""Splat scenes generated in code, with known answers, for renderer and probe-lighting tests and the demo.

- Radiance functions L(d) -> (M, 3) linear RGB of unit directions (``radiance_functions()``): a sky gradient with a
  closed-form irradiance, smooth "coloured walls", and a smooth environment with one small, very bright disc.
- ``shell_scene``: a closed, hole-free shell of thin splats around a centre whose colour seen from the centre is a
  given radiance function.
- ``room_scene``: a box-shaped room with openings (window, skylight) and a function saying which directions are holes.
- ``random_scene``: random splats in realistic ranges, fast for millions.
- ``sample_environment``: the small bundled demo environment (a room with coloured walls, a bright window, objects).
Coverage and colour along rays are checked with render.reference.composite_rays, the renderer's numpy reference.

All scenes are SH degree 0 unless said otherwise (``scene.with_sh_degree`` pads), Z is up, units are metres.
Their colours are scene-linear radiance (a lamp at 33 is HDR light, not an sRGB value): every scene made here
declares colour space "linear" (core/colour.py), and files written from them say so in their header.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .scene import SplatScene, rgb_to_sh_dc

RadianceFn = Callable[[np.ndarray], np.ndarray]
SYNTHETIC_COLOUR_SPACE = "linear"


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ---------------------------------------------------------------------------------------------------------------
# Radiance functions of direction

@dataclass(frozen=True)
class SkyGradient:
    """L(d) = a + b * d_z: smooth, and its irradiance is known exactly (it is pure SH bands 0 and 1)."""
    a: tuple[float, float, float] = (0.55, 0.65, 0.85)
    b: tuple[float, float, float] = (0.30, 0.35, 0.45)

    def __call__(self, dirs: np.ndarray) -> np.ndarray:
        d = np.asarray(dirs, np.float64)
        return np.asarray(self.a) + d[..., 2:3] * np.asarray(self.b)

    def irradiance_over_pi(self, normals: np.ndarray) -> np.ndarray:
        """E(n)/pi (the irradiance map's value): the cosine lobe keeps band 1 at 2/3, so a + 2/3 b n_z."""
        n = np.asarray(normals, np.float64)
        return np.asarray(self.a) + (2.0 / 3.0) * n[..., 2:3] * np.asarray(self.b)


@dataclass(frozen=True)
class ColouredWalls:
    """Smooth, with a distinct colour toward each of +X, -X, +Y, -Y, +Z, -Z: a blend weighted by |d_i|^p."""
    colours: tuple = ((0.9, 0.15, 0.1), (0.1, 0.7, 0.8),   # +X red, -X cyan
                      (0.15, 0.8, 0.2), (0.75, 0.2, 0.7),  # +Y green, -Y magenta
                      (0.95, 0.95, 0.9), (0.45, 0.3, 0.15))  # +Z white sky, -Z brown ground
    power: float = 4.0

    def __call__(self, dirs: np.ndarray) -> np.ndarray:
        d = np.asarray(dirs, np.float64)
        c = np.asarray(self.colours, np.float64).reshape(3, 2, 3)  # axis, sign (+, -), rgb
        w = np.abs(d) ** self.power
        w /= w.sum(-1, keepdims=True)
        side = np.where(d >= 0, 0, 1)  # (..., 3)
        picked = c[np.arange(3), side]  # (..., 3 axes, 3 rgb)
        return np.einsum("...a,...ac->...c", w, picked)


@dataclass(frozen=True)
class BrightPatch:
    """A smooth environment plus one small disc (hard edge) about ``intensity`` times brighter: a sun or a lamp.

    The disc's solid angle is exactly 2 pi (1 - cos radius), so its share of any integral is known.
    """
    direction: tuple[float, float, float] = (0.4, -0.3, 0.866)
    radius_deg: float = 7.0
    intensity: float = 80.0  # disc radiance relative to the base environment's mean (about 0.5)
    base: SkyGradient = field(default_factory=lambda: SkyGradient((0.45, 0.5, 0.6), (0.1, 0.12, 0.2)))
    colour: tuple[float, float, float] = (1.0, 0.95, 0.85)

    @property
    def disc_radiance(self) -> np.ndarray:
        return self.intensity * 0.5 * np.asarray(self.colour)

    @property
    def solid_angle(self) -> float:
        return 2.0 * np.pi * (1.0 - np.cos(np.radians(self.radius_deg)))

    def in_disc(self, dirs: np.ndarray) -> np.ndarray:
        return np.asarray(dirs, np.float64) @ _unit(self.direction) >= np.cos(np.radians(self.radius_deg))

    def __call__(self, dirs: np.ndarray) -> np.ndarray:
        return np.where(self.in_disc(dirs)[..., None], self.disc_radiance, self.base(dirs))


def radiance_functions() -> dict[str, RadianceFn]:
    """The analytic environments by name: 'sky' (gradient), 'walls' (coloured per axis), 'sun' (bright disc)."""
    return {"sky": SkyGradient(), "walls": ColouredWalls(), "sun": BrightPatch()}


# ---------------------------------------------------------------------------------------------------------------
# Geometry helpers

def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) nearly uniform unit directions (equal-area Fibonacci lattice)."""
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * (np.pi * (3.0 - np.sqrt(5.0)))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def quat_z_to(normals: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (w, x, y, z) rotating local +Z onto each unit normal (shortest arc)."""
    d = _unit(normals)
    q = np.stack([1.0 + d[:, 2], -d[:, 1], d[:, 0], np.zeros(len(d))], -1)
    n = np.linalg.norm(q, axis=1)
    flip = n < 1e-9  # normal == -Z: any half turn about a horizontal axis
    q[flip] = (0.0, 1.0, 0.0, 0.0)
    n[flip] = 1.0
    return q / n[:, None]


def _disks(centres: np.ndarray, normals: np.ndarray, rgb: np.ndarray, sigma: np.ndarray | float,
           flatness: float, opacity: float) -> SplatScene:
    """Thin splats tangent to the given normals: tangent sigma ``sigma``, normal sigma ``flatness * sigma``."""
    n = len(centres)
    sig = np.broadcast_to(np.asarray(sigma, np.float64), (n,))
    scales = np.stack([sig, sig, sig * flatness], -1)
    return SplatScene(np.asarray(centres, np.float32), scales.astype(np.float32),
                      quat_z_to(normals).astype(np.float32), np.full(n, opacity, np.float32),
                      rgb_to_sh_dc(np.asarray(rgb, np.float32))[:, None, :], source="<synthetic>",
                      colour_space=SYNTHETIC_COLOUR_SPACE)


def concat(scenes: list[SplatScene], source: str = "<synthetic>") -> SplatScene:
    """One scene holding all the splats of ``scenes`` (SH padded to the highest degree among them)."""
    deg = max(s.sh_degree for s in scenes)
    scenes = [s.with_sh_degree(deg) for s in scenes]
    return SplatScene(*(np.concatenate([getattr(s, f) for s in scenes]) for f in
                        ("positions", "scales", "rotations", "opacities", "sh")), source=source,
                      colour_space=SYNTHETIC_COLOUR_SPACE)


# ---------------------------------------------------------------------------------------------------------------
# Scenes

def shell_scene(radiance_fn: RadianceFn, n_splats: int, radius: float = 10.0,
                center: tuple[float, float, float] = (0.0, 0.0, 0.0), overlap: float = 1.0,
                flatness: float = 0.05, opacity: float = 0.99) -> SplatScene:
    """A closed sphere of thin splats whose colour seen from ``center`` along d is ``radiance_fn(d)``.

    Splats sit on a Fibonacci lattice, tangent to the sphere; the tangent sigma is ``overlap`` times the mean lattice
    spacing (radius * sqrt(4 pi / n)), which at the default leaves no hole seen from the centre (accumulated alpha
    > 0.99 in every direction); the radial sigma is ``flatness`` times that. Each splat's DC colour renders (SH degree
    0) exactly as the radiance at its own direction; what a renderer shows between splat centres is that radiance
    blurred over about one spacing.
    """
    # Shuffled: every splat sits at the same distance from the centre, so a renderer's depth sort leaves them in
    # storage order; the Fibonacci lattice's order runs pole to pole and would tint every pixel toward one pole.
    d = fibonacci_sphere(n_splats)[np.random.default_rng(n_splats).permutation(n_splats)]
    spacing = radius * np.sqrt(4.0 * np.pi / n_splats)
    rgb = radiance_fn(d)
    centres = np.asarray(center, np.float64) + radius * d
    return _disks(centres, d, rgb, overlap * spacing, flatness, opacity)


@dataclass
class RoomScene:
    """A box room of splats with rectangular openings, and the geometry to say which directions see a hole."""
    scene: SplatScene
    lo: np.ndarray  # (3,) box corner (floor level)
    hi: np.ndarray  # (3,) opposite corner (ceiling level)
    openings: list[tuple[int, int, tuple[float, float], tuple[float, float]]]
    # each opening: (axis of the wall's normal, side 0 = lo / 1 = hi, (u0, u1), (v0, v1)) where u, v are the two
    # other coordinates in increasing axis order
    sigma: float  # tangent sigma of the wall splats: openings' edges are blurred over about 2-3 sigma

    def _hits(self, point: np.ndarray, dirs: np.ndarray):
        p = np.asarray(point, np.float64)
        d = np.asarray(dirs, np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_hi = (self.hi - p) / d
            t_lo = (self.lo - p) / d
        t_exit = np.where(d > 0, t_hi, np.where(d < 0, t_lo, np.inf))  # (M, 3) per-axis exit distances
        axis = np.argmin(t_exit, -1)
        t = np.take_along_axis(t_exit, axis[:, None], 1)[:, 0]
        hit = p + t[:, None] * d
        side = (np.take_along_axis(d, axis[:, None], 1)[:, 0] > 0).astype(int)
        return axis, side, hit

    def edge_distance(self, point: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For rays from ``point`` (inside the box): (covered, distance in the wall plane from the hit point to the
        nearest opening edge). A test should trust ``covered`` only where the distance exceeds ~3 sigma."""
        axis, side, hit = self._hits(point, dirs)
        covered = np.ones(len(hit), bool)
        dist = np.full(len(hit), np.inf)
        for ax, sd, (u0, u1), (v0, v1) in self.openings:
            on = (axis == ax) & (side == sd)
            ua, va = [a for a in range(3) if a != ax]
            u, v = hit[:, ua], hit[:, va]
            inside = on & (u > u0) & (u < u1) & (v > v0) & (v < v1)
            covered &= ~inside
            # distance to the rectangle's boundary, within that wall's plane
            du = np.maximum(np.maximum(u0 - u, u - u1), 0.0)
            dv = np.maximum(np.maximum(v0 - v, v - v1), 0.0)
            outside_d = np.hypot(du, dv)
            inside_d = np.minimum(np.minimum(u - u0, u1 - u), np.minimum(v - v0, v1 - v))
            dist = np.where(on, np.minimum(dist, np.where(inside, inside_d, outside_d)), dist)
        return covered, dist

    def covered(self, point: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(M,) True where a ray from ``point`` along ``dirs`` should meet splats, False where it leaves by a hole."""
        return self.edge_distance(point, dirs)[0]


WALL_COLOURS = {  # (axis, side) -> linear RGB
    (0, 0): (0.7, 0.15, 0.1), (0, 1): (0.15, 0.3, 0.7),  # -X red, +X blue
    (1, 0): (0.2, 0.55, 0.2), (1, 1): (0.75, 0.65, 0.2),  # -Y green, +Y yellow
    (2, 0): (0.35, 0.25, 0.18), (2, 1): (0.85, 0.85, 0.82),  # floor brown, ceiling white
}


def room_scene(size: tuple[float, float, float] = (6.0, 5.0, 3.0), spacing: float = 0.1,
               window: tuple[tuple[float, float], tuple[float, float]] | None = ((-1.0, 1.0), (1.0, 2.2)),
               skylight: tuple[tuple[float, float], tuple[float, float]] | None = ((0.5, 1.5), (-2.0, -1.0)),
               colours: dict | None = None, overlap: float = 1.0, opacity: float = 0.99) -> RoomScene:
    """A room centred on the origin in x/y with its floor at z = 0: six walls of thin splats on a square grid.

    ``window`` is a hole in the +X wall given as ((y0, y1), (z0, z1)); ``skylight`` a hole in the ceiling given as
    ((x0, x1), (y0, y1)); None leaves the wall closed. Walls are coloured per side (``WALL_COLOURS``).
    """
    size = np.asarray(size, np.float64)
    lo = np.array([-size[0] / 2, -size[1] / 2, 0.0])
    hi = lo + size
    openings = []
    if window is not None:
        openings.append((0, 1, tuple(window[0]), tuple(window[1])))
    if skylight is not None:
        openings.append((2, 1, tuple(skylight[0]), tuple(skylight[1])))
    colours = {**WALL_COLOURS, **(colours or {})}
    parts = []
    for ax in range(3):
        ua, va = [a for a in range(3) if a != ax]
        gu = np.linspace(lo[ua], hi[ua], int(np.ceil(size[ua] / spacing)) + 1)
        gv = np.linspace(lo[va], hi[va], int(np.ceil(size[va] / spacing)) + 1)
        u, v = (g.ravel() for g in np.meshgrid(gu, gv, indexing="ij"))
        for side in (0, 1):
            keep = np.ones(len(u), bool)
            for oax, osd, (u0, u1), (v0, v1) in openings:
                if (oax, osd) == (ax, side):
                    keep &= ~((u > u0) & (u < u1) & (v > v0) & (v < v1))
            c = np.empty((int(keep.sum()), 3))
            c[:, ax] = hi[ax] if side else lo[ax]
            c[:, ua], c[:, va] = u[keep], v[keep]
            normal = np.zeros_like(c)
            normal[:, ax] = -1.0 if side else 1.0  # facing into the room
            rgb = np.broadcast_to(np.asarray(colours[(ax, side)], np.float64), c.shape)
            parts.append(_disks(c, normal, rgb, overlap * spacing, 0.05, opacity))
    return RoomScene(concat(parts, "<room>"), lo, hi, openings, overlap * spacing)


def random_scene(n: int, seed: int = 0, sh_degree: int = 3, extent: float = 1.0) -> SplatScene:
    """``n`` random splats in the box [-extent, extent]^3, in ranges like a trained 3DGS scene's.

    Log-scales ~ N(log(0.02 extent), 0.7) per axis (so splats are anisotropic, some needle-like), uniform random
    rotations, opacities = sigmoid(N(1, 2.5)) (many near 0 and 1, as trained scenes have), DC colours rendering as
    RGB in [0.02, 0.98], higher SH bands of standard deviation 0.15 / l (uniformly drawn). Vectorised float32 throughout
    (6M splats: a few seconds).
    """
    rng = np.random.default_rng(seed)
    f32 = np.float32
    pos = rng.random((n, 3), dtype=f32)
    pos *= f32(2.0 * extent)
    pos -= f32(extent)
    scales = rng.standard_normal((n, 3), dtype=f32)
    scales *= f32(0.7)
    scales += f32(np.log(0.02 * extent))
    np.exp(scales, out=scales)
    rot = rng.standard_normal((n, 4), dtype=f32)
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    opa = rng.standard_normal(n, dtype=f32)
    opa *= f32(-2.5)
    opa -= f32(1.0)
    np.exp(opa, out=opa)
    opa += f32(1.0)
    np.reciprocal(opa, out=opa)  # sigmoid(N(1, 2.5)), in place
    k = (sh_degree + 1) ** 2
    # Uniform in (-sqrt(3) sd, sqrt(3) sd) has standard deviation sd and is 5x cheaper to draw than a normal.
    sh = rng.random((n, k, 3), dtype=f32)
    sh -= f32(0.5)
    band_scale = np.array([0.96] + [2.0 * np.sqrt(3.0) * 0.15 / l for l in range(1, sh_degree + 1)
                                    for _ in range(2 * l + 1)], f32)
    sh *= band_scale[:, None]
    sh[:, 0] = rgb_to_sh_dc(sh[:, 0] + f32(0.5))  # DC renders as RGB uniform in [0.02, 0.98]
    return SplatScene(pos, scales, rot, opa, sh, source=f"<random n={n} seed={seed}>",
                      colour_space=SYNTHETIC_COLOUR_SPACE)


def sphere_object(centre, radius: float, rgb, spacing: float) -> SplatScene:
    """Closed sphere surface of thin splats (normals outward)."""
    n = max(64, int(4 * np.pi * radius ** 2 / spacing ** 2))
    d = fibonacci_sphere(n)
    return _disks(np.asarray(centre) + radius * d, d, np.broadcast_to(np.asarray(rgb, np.float64), d.shape),
                  spacing, 0.05, 0.99)


def _box_object(lo, hi, rgb, spacing: float) -> SplatScene:
    """Closed axis-aligned box surface of thin splats (normals outward)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    parts = []
    for ax in range(3):
        ua, va = [a for a in range(3) if a != ax]
        gu = np.linspace(lo[ua], hi[ua], max(2, int(np.ceil((hi[ua] - lo[ua]) / spacing)) + 1))
        gv = np.linspace(lo[va], hi[va], max(2, int(np.ceil((hi[va] - lo[va]) / spacing)) + 1))
        u, v = (g.ravel() for g in np.meshgrid(gu, gv, indexing="ij"))
        for side, sign in ((lo[ax], -1.0), (hi[ax], 1.0)):
            c = np.empty((len(u), 3))
            c[:, ax], c[:, ua], c[:, va] = side, u, v
            nrm = np.zeros_like(c)
            nrm[:, ax] = sign
            parts.append(_disks(c, nrm, np.broadcast_to(np.asarray(rgb, np.float64), c.shape), spacing, 0.05, 0.99))
    return concat(parts)


def sample_environment() -> SplatScene:
    """The bundled demo environment (~22k splats, deterministic): a 6 x 5 x 3 m room centred on the origin, floor at
    z = 0, coloured walls, a window in the +X wall with bright daylight behind it, a warm ceiling lamp, a table,
    a pillar and two spheres. Probe placed near (0, 0, 1) sees all of it."""
    spacing = 0.09
    room = room_scene((6.0, 5.0, 3.0), spacing, window=((-1.2, 1.2), (0.9, 2.3)), skylight=None).scene
    # Daylight: a bright panel just outside the window, slightly larger than the hole so no gap shows at its edge.
    yy, zz = np.meshgrid(np.arange(-1.4, 1.41, spacing), np.arange(0.7, 2.51, spacing), indexing="ij")
    n = yy.size
    sky = _disks(np.stack([np.full(n, 3.3), yy.ravel(), zz.ravel()], -1), np.tile([-1.0, 0, 0], (n, 1)),
                 np.tile([6.0, 7.0, 8.5], (n, 1)), spacing, 0.05, 0.99)
    lamp = shell_scene(lambda d: np.tile([40.0, 32.0, 22.0], (len(d), 1)), 400, 0.12, (0.0, 0.0, 2.75), flatness=0.3)
    objects = [
        _box_object((-1.5, -1.2, 0.70), (-0.3, -0.2, 0.76), (0.5, 0.32, 0.18), spacing * 0.6),  # table top
        *(_box_object((x - 0.04, y - 0.04, 0.0), (x + 0.04, y + 0.04, 0.7), (0.3, 0.2, 0.12), spacing * 0.5)
          for x in (-1.45, -0.35) for y in (-1.15, -0.25)),  # legs
        _box_object((1.8, 1.6, 0.0), (2.2, 2.0, 3.0), (0.8, 0.8, 0.78), spacing * 0.7),  # pillar
        sphere_object((-1.0, -0.7, 0.98), 0.22, (0.9, 0.75, 0.1), spacing * 0.5),  # on the table
        sphere_object((1.2, -1.5, 0.4), 0.4, (0.1, 0.35, 0.8), spacing * 0.6),  # on the floor
    ]
    return concat([room, sky, lamp, *objects], "<sample environment>")
