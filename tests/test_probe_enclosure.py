"""A probe inside an object of the capture (issue 35): a probe in a coloured armchair, many sigmas from every splat
of its shell, gave blue-green meshes and no warning. core/probe/near.py's enclosure check: how much of the probe's
view, all around it, is hidden by splats close to it."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core.probe.near import ENCLOSED, NEAR_SIGMAS, enclosure, near_splats, near_warning
from gs_ibl_addon.core.synthetic import SkyGradient, concat, room_scene, shell_scene

CHAIR = (1.0, 0.5, 0.5)


@pytest.fixture(scope="module")
def room():
    return room_scene()  # 6 x 5 x 3 m, walls of 5 mm splats 10 cm apart


def _chair(opacity=0.99, radius=0.35):
    return shell_scene(SkyGradient(), 2000, radius, CHAIR, opacity=opacity)  # a closed shell of splats


def test_a_probe_inside_a_closed_shell_of_splats_is_warned(room):
    scene = concat([room.scene, _chair()])
    rec = near_splats(scene, CHAIR)
    assert rec["nearest_sigmas"] > NEAR_SIGMAS  # far from every splat in their sigmas: the old check said nothing
    assert rec["enclosed"] > 0.95 and rec["enclosed_around"] > ENCLOSED
    assert rec["enclosure_distance"] == pytest.approx(0.35, rel=0.05)
    warning = near_warning(rec, "Armchair")
    assert warning.startswith("the probe is inside splats of 'Armchair': ") and "all around it" in warning
    assert "move the probe out into open space" in warning
    assert "inside splats:" in near_warning(rec)  # the command line names no object
    # anywhere inside it, and at any opacity that hides what is behind: one layer of 0.3 leaves 15% seen
    assert enclosure(scene, (1.0, 0.5, 0.25))["around"] > ENCLOSED
    faint = enclosure(concat([room.scene, _chair(opacity=0.3)]), CHAIR)
    assert faint["around"] > ENCLOSED
    almost_clear = enclosure(concat([room.scene, _chair(opacity=0.03)]), CHAIR)
    assert almost_clear["around"] < 0.5


@pytest.mark.parametrize("where", [(0.0, 0.0, 1.5),  # the room's open middle
                                   (1.0, 0.5, 0.95),  # on the chair's top
                                   (0.0, 0.0, 0.1),  # 10 cm above the floor
                                   (-2.7, -2.2, 0.3)])  # 30 cm from a corner: three walls close, a half open
def test_a_probe_beside_walls_or_on_an_object_is_not_inside(room, where):
    scene = concat([room.scene, _chair()])
    rec = near_splats(scene, where)
    assert rec["enclosed_around"] < ENCLOSED, rec
    assert near_warning(rec) is None or "all around it" not in near_warning(rec)


def test_enclosure_reads_only_the_splats_near_the_probe(room):
    far = enclosure(room.scene, (0.0, 0.0, 1.5))
    assert far["enclosed"] == 0.0 and far["distance"] is None
    assert far["radius"] == pytest.approx(0.1 * np.linalg.norm(np.percentile(room.scene.positions, 95, 0)
                                                               - np.percentile(room.scene.positions, 5, 0)))
