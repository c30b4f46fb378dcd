"""The panel after a bake and an F12 frame with the splats, as a user gets them, in the real Blender 5.2 binary with
its GUI (Debian sid root, Xvfb): the built zip installed by Blender's own installer, then gui_render.py run there
(see its docstring). Checked:
- Add GS-IBL Probe and Bake / Refresh, called as the panel's buttons call them, bake the room (the bake a modal job);
  a real click opens the sidebar's GS-IBL tab;
- a real F12 key opens the render window and renders the frame as a job, and the render handler draws the room's
  splats into it (all of them, no message); the panel's line says F12 has the meshes and the room's splats;
- the rendered frame holds the splats and the meshes, by depth: mostly coloured (the room's walls), not Blender's
  flat grey World; the blue splat ball is blue, also where the white sphere is behind it; the sphere's part beside
  the ball and Suzanne are grey (the meshes, in front of the walls); the red wall behind them is red.
Skipped unless the sid root has been made (scripts/blender_roots.sh ensure sid). Screenshots land in
build/matrix/gui-render/; the sidebar crop and the render window's crop for docs/img (blender_panel.png,
blender_f12_window.png) in build/matrix/gui-render/docs/.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from test_matrix import REPO, Entry, run_gui_script

ENTRY = Entry("gui-render", "sid", True, gui=True)
ROOM_SPLATS = 21_939


def _read(path: Path) -> np.ndarray:
    """A PNG as float RGB in 0..1, row 0 at the top."""
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, f"cannot read {path}: {buf.geterror()}"
    return buf.get_pixels(oiio.FLOAT)[..., :3]


def _write(path: Path, rgb: np.ndarray) -> None:
    import OpenImageIO as oiio
    path.parent.mkdir(parents=True, exist_ok=True)
    px = np.ascontiguousarray(np.clip(rgb * 255.0 + 0.5, 0, 255).astype(np.uint8))
    out = oiio.ImageBuf(oiio.ImageSpec(px.shape[1], px.shape[0], 3, oiio.UINT8))
    out.set_pixels(oiio.ROI(), px)
    out.write(str(path))


def panel_crop(screen: np.ndarray, region, window) -> np.ndarray:
    """The sidebar (x, y from the window's bottom, width, height) of a screenshot of the window filling the screen,
    down to the bottom of its panel (the sidebar lies over the 3D View, whose grid shows below the panel): the
    panel's outline runs down its left edge, 8 px in."""
    x, y, w, h = region
    top = window[1] - y - h
    ui = screen[top:top + h, x:x + w]
    edge = ui[:, 8]
    outline = np.nonzero(np.abs(edge - edge[40]).max(-1) < 0.01)[0]
    return ui[: min(h, outline[-1] + 10)] if len(outline) > 200 else ui


def window_crop(screen: np.ndarray, windows: list[dict]) -> np.ndarray:
    """The render window: the X window that is not the main one (the main one fills the screen)."""
    h, w = screen.shape[:2]
    others = [x for x in windows if (x.get("width"), x.get("height")) != (w, h) and x.get("width", 0) > 100]
    assert others, f"no render window among {windows}"
    win = max(others, key=lambda x: x["width"] * x["height"])
    return screen[win["y"]:win["y"] + win["height"], win["x"]:win["x"] + win["width"]]


def _patch(img: np.ndarray, col: float, row: float, r: int = 2) -> np.ndarray:
    c, rr = int(round(col)), int(round(row))
    return np.median(img[rr - r:rr + r + 1, c - r:c + r + 1].reshape(-1, 3), 0)


def chroma(rgb: np.ndarray) -> np.ndarray:
    return rgb.max(-1) - rgb.min(-1)


def frame_checks(img: np.ndarray, f12: dict) -> list[str]:
    """What the rendered frame must hold (gui_render.py's scene); the problems found."""
    problems = []
    h, w = img.shape[:2]
    if [w, h] != f12["size"]:
        problems.append(f"the frame is {w}x{h}, not {f12['size']}")
        return problems
    coloured = float((chroma(img) > 0.15).mean())
    print(f"[gui-render] frame: {coloured:.0%} of its pixels coloured, spread {img.std((0, 1)).round(3)}")
    if coloured < 0.4:
        problems.append(f"only {coloured:.0%} of the frame is coloured: the room's splats are missing")
    ball, sphere = f12["blue_ball"], f12["sphere"]
    bc, sc = np.array(ball["centre"]), np.array(sphere["centre"])
    d = np.linalg.norm(sc - bc)
    samples = {"blue ball": bc,
               # where the ball (splats, nearer) covers the sphere (a mesh, further): the splats in front
               "ball over the sphere": bc + (sc - bc) / d * (d - 0.5 * sphere["radius"]),
               # the sphere's side away from the ball: the mesh, in front of the floor and walls
               "sphere": sc + (sc - bc) / d * 0.5 * sphere["radius"],
               "Suzanne": np.array(f12["monkey"]), "red wall": np.array(f12["red_wall"])}
    if ball["depth"] >= sphere["depth"] or d > ball["radius"] + 0.5 * sphere["radius"]:
        problems.append(f"the scene is not as set: the ball should partly hide the sphere ({ball}, {sphere})")
    for name, (col, row) in samples.items():
        rgb = _patch(img, col, row)
        print(f"[gui-render] {name} at ({col:.0f}, {row:.0f}): {rgb.round(3)}")
        r, g, b = rgb
        ok = {"blue ball": b > r + 0.2 and b > g + 0.05, "ball over the sphere": b > r + 0.2 and b > g + 0.05,
              "sphere": chroma(rgb) < 0.12 and rgb.mean() > 0.35, "Suzanne": chroma(rgb) < 0.12 and rgb.mean() > 0.2,
              "red wall": r > g + 0.25 and r > b + 0.25}[name]
        if not ok:
            problems.append(f"{name} at ({col:.0f}, {row:.0f}) is {rgb.round(3)}")
    return problems


def test_gui_render(tmp_path_factory):
    result, out, keep = run_gui_script(ENTRY, tmp_path_factory.mktemp("gui-render"), "gui_render.py", "render.json",
                                       "--room {inner}/room.ply",
                                       inputs=(REPO / "samples" / "room.ply",))
    steps = result["steps"]
    for name in ("add_probe", "bake_probe", "bake", "tab", "panel"):
        print(f"[gui-render] {name}: {json.dumps(steps.get(name))[:600]}")
    f12 = steps["f12"]
    print(f"[gui-render] f12: {json.dumps({k: v for k, v in f12.items() if k != 'windows'})[:1500]}")
    docs = keep / "docs"

    assert steps["add_probe"] == ["FINISHED"] and steps["bake_probe"] == ["RUNNING_MODAL"], steps
    bake = steps["bake"]
    assert bake["report"].startswith("Baked ") and bake["world"] == bake["probe_world"], bake
    assert bake["parent"] == result["meshes"][0], bake  # placed at the selected sphere, following it

    panel = steps["panel"]
    assert panel["tab"] == "GS-IBL", (panel, result["tab_clicks"])
    _write(docs / "blender_panel.png", panel_crop(_read(out / panel["png"]), panel["region"], panel["window"]))

    assert f12["render_started_s"] < 20 and f12["render_s"] < 300, f12
    assert len(f12["windows"]) > f12["windows_before"], "F12 opened no render window"
    assert f12["describe"].startswith("F12: meshes and the splats of room, by depth; "), f12["describe"]
    record = f12["record"]
    assert not record["messages"] and not record["cancelled"], record
    frames = list(record["frames"].values())
    assert len(frames) == 1 and frames[0]["splats"] == ROOM_SPLATS and frames[0]["objects"] == ["room"], record
    assert frames[0]["triangles"] > 0, record  # the meshes' depth was taken

    screen = _read(out / f12["png"])
    window = window_crop(screen, f12["x_windows"])
    _write(docs / "blender_f12_window.png", window)
    # the frame is shown in the render window: its splats' colours are there
    assert (chroma(window) > 0.3).mean() > 0.1, "the render window does not show the frame"

    problems = frame_checks(_read(out / f12["result"]), f12)
    assert not problems, f"Blender {result['blender']} (see {keep}):\n" + "\n".join(problems)
