"""The scene camera of a frame being rendered, as our renderer and the mesh raster take it, and what about it the
splats cannot follow (each a message naming the setting).

Everything is read from the render pipeline's depsgraph, evaluated at the frame (docs/final-frame.md, section 2):
``calc_matrix_camera`` with the output size and pixel aspect gives the frustum (lens, sensor fit, shift), the
render border gives the window.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.render.mesh_depth import frustum_from_projection


class NotDrawn(Exception):
    """The splats cannot be drawn for this render: the message says why and which setting to change."""


@dataclass(frozen=True)
class FrameCamera:
    name: str
    matrix: np.ndarray  # camera to world, 4x4 (as Blender has it; scale is taken out by the users)
    tan_x: float
    tan_y: float
    cx: float  # lens shift: the frame's centre at distance 1, right and up
    cy: float
    width: int  # the frame's pixels (resolution at its percentage)
    height: int
    window: tuple[int, int, int, int] | None  # the render border: x0, y0, x1, y1 of the frame, rows from the top
    crop: bool  # the render (and our images) are the window's size; else the frame's, splats only in the window
    clip_start: float
    clip_end: float

    @property
    def image_size(self) -> tuple[int, int]:
        """The size of the images the compositor reads (output_size in compositor.py)."""
        if self.window is not None and self.crop:
            x0, y0, x1, y1 = self.window
            return x1 - x0, y1 - y0
        return self.width, self.height


def frame_camera(dg) -> FrameCamera:
    """The camera of the frame ``dg`` (the render pipeline's depsgraph) renders. Raises NotDrawn where the splats
    cannot be drawn from it."""
    se = dg.scene_eval
    r = se.render
    cam_obj = se.camera
    if cam_obj is None:
        raise NotDrawn("the scene has no camera (Scene Properties > Camera)")
    cam = cam_obj.evaluated_get(dg)
    data = cam.data
    if data.type != "PERSP":
        kind = {"ORTHO": "orthographic", "PANO": "panoramic"}.get(data.type, data.type.lower())
        raise NotDrawn(f"splats are drawn for perspective cameras only: camera '{cam_obj.name}' is {kind} "
                       "(Camera Properties > Lens > Type)")
    w = r.resolution_x * r.resolution_percentage // 100
    h = r.resolution_y * r.resolution_percentage // 100
    proj = np.array(cam.calc_matrix_camera(dg, x=w, y=h, scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y))
    tan_x, tan_y, cx, cy = frustum_from_projection(proj)
    window = None
    if r.use_border:
        x0, x1 = int(r.border_min_x * w), int(r.border_max_x * w)
        y0b, y1b = int(r.border_min_y * h), int(r.border_max_y * h)  # Blender counts rows from the bottom
        if x1 > x0 and y1b > y0b:
            window = (x0, h - y1b, x1, h - y0b)
    return FrameCamera(cam_obj.name, np.array(cam.matrix_world, np.float64), tan_x, tan_y, cx, cy, w, h, window,
                       bool(r.use_border and r.use_crop_to_border), float(data.clip_start), float(data.clip_end))


def not_followed(dg) -> list[str]:
    """Settings of this render the splats are drawn without (said once per render)."""
    se = dg.scene_eval
    out = []
    cam = se.camera
    if cam is not None and cam.data.type == "PERSP" and cam.data.dof.use_dof:
        out.append(f"depth of field is not applied to the splats (camera '{cam.name}': Camera Properties > Depth of "
                   "Field): they are drawn sharp")
    if se.render.use_motion_blur:
        out.append("motion blur is not applied to the splats (Render Properties > Motion Blur): each frame draws "
                   "them at its own instant")
    return out
