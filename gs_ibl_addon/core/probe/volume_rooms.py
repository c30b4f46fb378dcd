"""The light volume's leak scene (issue 37): a bright room and a dark room side by side, one splat wall between them
(each room's own wall, 10 cm apart), with the exact irradiance of points in the dark room.

Each room is a closed synthetic.room_scene (3 x 3 x 2.5 m, walls of thin splats): the bright room's far wall (-X)
shines at BRIGHT, every other wall of both rooms is synthetic.WALL_COLOURS x DIM. A point in the dark room sees only
the dark room's walls, so its exact E/pi is the cosine integral of their known colours (``exact``: ray against the
box, the colour of the wall it meets). The splats are shuffled (storage order is not under test).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import SplatScene
from ..synthetic import WALL_COLOURS, concat, fibonacci_sphere, room_scene, sphere_object
from .grid import GridSpec

SIZE = (3.0, 3.0, 2.5)
GAP = 0.1  # between the two rooms' walls at x = 0: two layers of splats, each opaque on its own
BRIGHT = 8.0
DIM = 0.25
SPACING = 0.1


@dataclass
class TwoRooms:
    scene: SplatScene
    dark_lo: np.ndarray
    dark_hi: np.ndarray

    def exact(self, points: np.ndarray, normals: np.ndarray, directions: int = 20000) -> np.ndarray:
        """E/pi (M, 3) at points inside the dark room with unit normals: the cosine integral of the dark room's
        wall colours by quadrature over Fibonacci directions."""
        w = fibonacci_sphere(directions)
        out = np.empty((len(points), 3))
        for k, (p, n) in enumerate(zip(np.asarray(points, np.float64), np.asarray(normals, np.float64))):
            with np.errstate(divide="ignore"):
                t = np.where(w > 0, (self.dark_hi - p) / w, np.where(w < 0, (self.dark_lo - p) / w, np.inf))
            axis = np.argmin(t, 1)
            side = (w[np.arange(len(w)), axis] > 0).astype(int)
            colours = DIM * np.array([[WALL_COLOURS[(a, s)] for s in (0, 1)] for a in range(3)])
            out[k] = np.maximum(w @ n, 0.0) @ colours[axis, side] * (4.0 / len(w))
        return out


def _room(centre_x: float, colours: dict) -> SplatScene:
    room = room_scene(SIZE, SPACING, window=None, skylight=None, colours=colours).scene
    m = np.eye(4)
    m[0, 3] = centre_x
    return room.transformed(m)


def two_rooms(seed: int = 0) -> TwoRooms:
    """The scene: the bright room at x < -GAP/2, the dark room at x > GAP/2, floors at z = 0."""
    dim = {k: tuple(DIM * c for c in v) for k, v in WALL_COLOURS.items()}
    half = SIZE[0] / 2 + GAP / 2
    bright = _room(-half, {**dim, (0, 0): (BRIGHT,) * 3})
    dark = _room(half, dim)
    scene = concat([bright, dark], "<two rooms>")
    scene = scene.subset(np.random.default_rng(seed).permutation(scene.count))
    lo = np.array([GAP / 2, -SIZE[1] / 2, 0.0])
    return TwoRooms(scene, lo, lo + np.asarray(SIZE))


# Nodes 0.4 m apart on both sides of the wall: x -0.5, -0.1 (the bright room), 0.3, 0.7, 1.1; the cell from -0.1 to
# 0.3 spans the wall, and the sphere (x 0.2 to 0.7, 0.15 m from the dark room's wall at its nearest) reaches into it.
LEAK_SPEC = GridSpec((-0.5, -0.4, 0.8), (1.1, 0.4, 1.6), (5, 3, 3))
SPHERE_CENTRE, SPHERE_RADIUS = (0.45, 0.0, 1.2), 0.25


def sphere_points(n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """(points, normals) on the leak test's sphere."""
    d = fibonacci_sphere(n)
    return np.asarray(SPHERE_CENTRE) + SPHERE_RADIUS * d, d


# The bricks' scene (volume_refine.py): a closed room with a small bright ball where the grid's nodes are 0.9-1 m
# apart. LAMP_SPEC's nodes: x, y -1, 0, 1; z 0.5, 1.4, 2.3; the ball sits inside cell (1, 1, 1), the sphere of
# points 0.4 m below it in the same cell, where the light falls as ~1/d^2 between the nodes.
LAMP, LAMP_RADIUS, LAMP_RADIANCE = (0.3, 0.35, 1.95), 0.08, 40.0
LAMP_SPEC = GridSpec((-1.0, -1.0, 0.5), (1.0, 1.0, 2.3), (3, 3, 3))
BELOW_LAMP, BELOW_RADIUS = (0.3, 0.35, 1.5), 0.15


def lamp_room(seed: int = 0) -> SplatScene:
    """A closed 3 x 3 x 2.5 m room (walls WALL_COLOURS x DIM x 2) with a ball of radiance LAMP_RADIANCE at LAMP;
    storage order shuffled."""
    room = _room(0.0, {k: tuple(2 * DIM * c for c in v) for k, v in WALL_COLOURS.items()})
    scene = concat([room, sphere_object(LAMP, LAMP_RADIUS, (LAMP_RADIANCE,) * 3, 0.03)], "<lamp room>")
    return scene.subset(np.random.default_rng(seed).permutation(scene.count))
