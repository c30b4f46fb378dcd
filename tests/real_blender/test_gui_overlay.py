"""The viewport overlay as a user sees it, in the real Blender 5.2 binary with its GUI (Debian sid root, Xvfb).

The built zip is installed with Blender's own installer into a fresh user directory (as test_matrix.py does), then
gui_overlay.py runs in that Blender, takes screenshots and sends real clicks and keys with xdotool (see its
docstring). Checked here:
- the overlay's shaders against their numpy references: the plain quads and the composite (overlay_math.composite)
  offscreen on inputs that take each of its branches, and the composite as drawn in the viewport on the real overlay
  layer (8-bit, within 2 levels);
- no black vertex dots, grid or other helper drawing inside the splat region: with Show Splats on, the screenshot
  with Blender's overlays on equals the one with them off wherever the splats cover the view (overlays off, Blender
  can draw neither), from inside the room and of its wall from outside (where the floor grid, which writes its
  depth, showed through the wall's lower band: issue 21 item 6);
- a mesh in front of splats hides them (the Occluder cube looks as without splats); splats in front of a mesh hide
  it (the red Blob is seen where the Backdrop cube is behind it);
- while the view moves the splats are drawn at the moving resolution, and once it is still one timed redraw (no
  event) draws them at the Resolution setting;
- issue 21 item 2: Shift+right-click on the floor splats puts the 3D cursor within 2 cm of the floor point under
  the mouse; the cursor and a selected object's origin dot show over the splats; clicking the splats selects their
  object, clicking a mesh in front of them the mesh, Shift+click adds;
- issue 21 item 6: a mesh edge over the splats is as smooth as over Blender's plain background (the scatter of its
  sub-pixel edge positions about a straight line, in pixels, with and without splats; the old plain-quad draw's too);
- File > Import turns Show Splats on (issue 21 item 3), and Update When Moved re-bakes once when a mesh a probe
  follows is moved with G in the viewport, not again on Ctrl+Z, after which the report is the one of the World in
  use (item 5).
Skipped unless the sid root has been made (scripts/blender_roots.sh ensure sid). Screenshots land in
build/matrix/gui-overlay/, crops for docs/img in build/matrix/gui-overlay/docs/.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gs_ibl_addon.blender.viewport.overlay_math import MOVING_SCALE
from test_matrix import REPO, Entry, run_gui_script

ENTRY = Entry("gui-overlay", "sid", True, gui=True)
HEADER_PX = 60  # the region's top rows hold the header's buttons, whose highlight follows the overlays toggle
COVERED = 0.95  # the splat region: pixels the room's splats cover at least this much
DIFF = 0.08  # a pixel differs when a channel differs by more than this (8-bit screenshots of the same image: 0)
MAX_DIFFERING = 5e-4  # at most this fraction of the splat region may differ (a dot per ~2000 pixels)
CURSOR_TOLERANCE_M = 0.02  # the cursor placed on the splat floor: distance to the floor point under the mouse
EDGE_SLACK_PX = 0.05  # a mesh edge over splats: its roughness may exceed the plain background's by this much


def _read(path: Path) -> np.ndarray:
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise AssertionError(f"cannot read screenshot {path}: {buf.geterror()}")
    return buf.get_pixels(oiio.FLOAT)[..., :3]


def _write(path: Path, rgb: np.ndarray) -> None:
    import OpenImageIO as oiio
    px = np.ascontiguousarray(np.clip(rgb * 255.0 + 0.5, 0, 255).astype(np.uint8))
    out = oiio.ImageBuf(oiio.ImageSpec(px.shape[1], px.shape[0], 3, oiio.UINT8))
    out.set_pixels(oiio.ROI(), px)
    out.write(str(path))


def _region(shot: dict, out: Path) -> np.ndarray:
    """The 3D region's pixels of a screenshot, row 0 at the top (the window fills the X screen from its corner)."""
    x, y, w, h = shot["region"]
    top = shot["window"][1] - y - h
    return _read(out / shot["png"])[top:top + h, x:x + w]


def _splat_region(shot: dict, out: Path) -> np.ndarray:
    """Region pixels well covered by the room's splats: the overlay's own coverage image, sampled at each pixel."""
    cov = np.load(out / shot["coverage"])
    _x, _y, w, h = shot["region"]
    x0, y0, x1, y1 = shot["coverage_rect"]
    ndc_x = (np.arange(w) + 0.5) / w * 2 - 1
    ndc_y = 1 - (np.arange(h) + 0.5) / h * 2  # rows top first
    u = np.clip(((ndc_x - x0) / (x1 - x0) * cov.shape[1]).astype(int), 0, cov.shape[1] - 1)
    v = np.clip(((y1 - ndc_y) / (y1 - y0) * cov.shape[0]).astype(int), 0, cov.shape[0] - 1)
    mask = cov[v[:, None], u[None, :]] > COVERED
    mask[:HEADER_PX] = False
    return mask


def _patch(img: np.ndarray, shot: dict, name: str, r: int = 4) -> np.ndarray:
    """Mean colour of a small square around a test object's projected centre."""
    px, py, _z = shot["points"][name]
    row, col = int(shot["region"][3] - py), int(px)
    return img[row - r:row + r + 1, col - r:col + r + 1].reshape(-1, 3).mean(0)


def _project(shot: dict, point) -> tuple[float, float]:
    """A world point -> region pixel (x right, y up) through the shot's matrices."""
    clip = np.array(shot["window_matrix"]) @ np.array(shot["view_matrix"]) @ np.array([*point, 1.0])
    _x, _y, w, h = shot["region"]
    return (clip[0] / clip[3] + 1) / 2 * w, (clip[1] / clip[3] + 1) / 2 * h


def _cursor_pixels(img: np.ndarray, shot: dict, point, radius: float) -> int:
    """Pixels of the 3D cursor's red and white circle (radius half a widget unit) around its projection."""
    cx, cy = _project(shot, point)
    h = img.shape[0]
    rows, cols = np.mgrid[0:h, 0:img.shape[1]]
    dist = np.hypot(cols + 0.5 - cx, (h - rows - 0.5) - cy)
    ring = np.abs(dist - radius) <= 1.5
    red = (img[..., 0] > 0.6) & (img[..., 1] < 0.3) & (img[..., 2] < 0.3)
    white = img.min(-1) > 0.85
    return int((ring & (red | white)).sum())


def edge_roughness(img: np.ndarray, corners) -> tuple[float, int]:
    """How far the sub-pixel positions of a straight mesh edge scatter about a line (RMS, pixels), and how many
    columns were measured: per column along the middle 60% of the plane's top edge, the row where the brightness
    crosses halfway between the plane's (4-6 pixels inside) and what is behind it (4-6 pixels outside). An
    anti-aliased edge follows its line within ~0.1 pixel; a stair-stepped one scatters by ~0.3 (a pixel's
    quantisation)."""
    h = img.shape[0]
    top = sorted(corners, key=lambda c: -c[1])[:2]
    (x0, y0), (x1, y1) = sorted(top)
    lum = img.mean(-1)
    xs, rows = [], []
    for col in range(int(x0 + 0.2 * (x1 - x0)), int(x1 - 0.2 * (x1 - x0))):
        t = (col + 0.5 - x0) / (x1 - x0)
        r0 = int(h - (y0 + t * (y1 - y0)))
        if r0 - 7 < 0 or r0 + 7 >= h:
            continue
        prof = lum[r0 - 7:r0 + 8, col]
        outside, inside = prof[1:4].mean(), prof[11:14].mean()
        if abs(inside - outside) < 0.05:
            continue
        mid = 0.5 * (inside + outside)
        s = np.sign(prof - mid)
        cross = [i for i in range(3, 12) if s[i] != s[i + 1] and s[i] != 0]
        if len(cross) != 1:
            continue
        i = cross[0]
        f = (mid - prof[i]) / (prof[i + 1] - prof[i])
        xs.append(col + 0.5)
        rows.append(r0 - 7 + i + f)
    if len(xs) < 20:
        return float("nan"), len(xs)
    fit = np.polyfit(xs, rows, 1)
    return float(np.sqrt(np.mean((np.array(rows) - np.polyval(fit, xs)) ** 2))), len(xs)


def _crop_around(img: np.ndarray, cx: float, cy: float, w: int, h: int) -> np.ndarray:
    rows = img.shape[0]
    r = int(np.clip(rows - cy - h / 2, 0, rows - h))
    c = int(np.clip(cx - w / 2, 0, img.shape[1] - w))
    return img[r:r + h, c:c + w]


def test_gui_overlay(tmp_path_factory):
    result, out, keep = run_gui_script(ENTRY, tmp_path_factory.mktemp("gui"), "gui_overlay.py", "shots.json",
                                       "--room {inner}/room.ply", inputs=(REPO / "samples" / "room.ply",))
    problems = analyse(result, out, keep / "docs")
    assert not problems, f"Blender {result['blender']} (screenshots in {keep}):\n" + "\n".join(problems)


def analyse(result: dict, out: Path, docs: Path) -> list[str]:
    """The checks on what gui_overlay.py recorded (shots.json and the screenshots in ``out``); crops for docs/img
    are written to ``docs``. Returns the problems found (printing what each check measured)."""
    docs.mkdir(parents=True, exist_ok=True)
    problems = []

    # the overlay's shaders are their numpy references', to float precision (offscreen, every branch) and within
    # two 8-bit levels in the viewport itself
    check = result["shader_check"]
    assert check["colour_max_error"] < 1e-4 and check["depth_max_error"] < 1e-5, check
    for n, comp in result["composite_check"].items():
        print(f"[gui-overlay] composite shader offscreen, {n} splat layer(s): max error {comp['max_error']:.2e} over "
              f"{comp['written']} pixels written, per kind {comp['kinds_written']}, {comp['in_discs']} line pixels "
              f"in cursor discs")
        if not (comp["max_error"] < 1e-4 and min(comp["kinds_written"].values()) > 0 and comp["in_discs"] > 0):
            problems.append(f"the composite shader differs from overlay_math.composite offscreen ({n} layers): {comp}")
    real = result["composite_real"]
    print(f"[gui-overlay] composite in the viewport vs numpy on the same overlay layer: {real}")
    if "error" in real or real["max_diff_8bit"] > 2.0 or not real["grid"] or real["discs"] < 1:
        problems.append(f"the composite drawn in the viewport differs from overlay_math.composite: {real}")

    shots = result["shots"]
    for view in ("a", "b", "w"):
        on, clean, plain = shots[f"{view}_splats"], shots[f"{view}_clean"], shots[f"{view}_plain"]
        assert on["error"] is None, f"the overlay's draw handler failed: {on['error']}"
        img_on, img_clean, img_plain = _region(on, out), _region(clean, out), _region(plain, out)
        mask = _splat_region(on, out)
        assert mask.mean() > 0.3, f"view {view}: the splats cover only {mask.mean():.0%} of the view"
        differs = (np.abs(img_on - img_clean).max(-1) > DIFF) & mask
        dark = ((img_clean.mean(-1) - img_on.mean(-1)) > 0.2) & mask
        frac = differs.sum() / mask.sum()
        print(f"[gui-overlay] view {view}: splat region {mask.mean():.0%} of the view, {frac:.4%} of it "
              f"({differs.sum()} pixels) differs with Blender's overlays on ({dark.sum()} pixels darker, as dots, "
              f"lines or grid would be)")
        if frac > MAX_DIFFERING:
            problems.append(f"view {view}: with Blender's overlays on, {frac:.3%} of the splat region differs from "
                            f"overlays off ({dark.sum()} pixels darker): helper dots, lines or grid over the splats")
        if view == "w":
            quads = _region(shots["w_quads"], out)
            before = ((np.abs(quads - img_clean).max(-1) > DIFF) & mask).sum()
            print(f"[gui-overlay] the wall from outside: {differs.sum()} grid pixels inside it "
                  f"(the plain-quad draw: {before})")
            _write(docs / "blender_overlay_wall_outside.png", img_on[HEADER_PX:][::2, ::2])
            continue
        # a mesh in front of splats hides them: the Occluder looks as it does without splats
        occ_on, occ_plain = _patch(img_on, on, "occluder"), _patch(img_plain, plain, "occluder")
        if np.abs(occ_on - occ_plain).max() > 0.03:
            problems.append(f"view {view}: the Occluder cube in front of the splats is covered by them "
                            f"({occ_on.round(3)} vs {occ_plain.round(3)} without splats)")
        # splats in front of a mesh hide it: the red Blob is seen, not the grey Backdrop behind it
        blob = _patch(img_on, on, "blob")
        if not blob[0] > blob[1] + 0.25:
            problems.append(f"view {view}: the red splat ball in front of the Backdrop cube is hidden "
                            f"({blob.round(3)})")

    # while the view moved the splats were drawn coarse; once still, a timed redraw drew them at the Resolution
    motion = result["motion"]
    draws = [(t, s) for t, s, _ms, _dms in motion["draws"]]
    moving = [s for t, s in draws if t <= motion["last_nudge"] + 0.2]
    after = [(t, s) for t, s in draws if t > motion["last_nudge"]]
    print(f"[gui-overlay] draws around the orbit (time after the last view change, scale): "
          f"{[(round(t - motion['last_nudge'], 2), s) for t, s in draws[-8:]]}")
    if MOVING_SCALE not in moving:
        problems.append(f"no coarse ({MOVING_SCALE}) draw while the view moved: {draws[-8:]}")
    if not after or after[-1][1] != motion["resolution"] or after[-1][0] < motion["last_nudge"] + 0.2:
        problems.append(f"no full-resolution redraw ({motion['resolution']}) once the view was still: {after}")
    # what a redraw of an unchanged view costs in the draw handler (the splat image itself is not rendered again)
    cost = {}
    for tag in ("composite", "quads"):
        log = result["draw_log"][tag][1:]  # the first redraw may have rendered a new image
        times = [t for t, _s, _ms, _d in log]
        cost[tag] = {"redraws": len(log), "handler_ms": round(float(np.median([d for *_x, d in log])), 1) if log
                     else None, "redraws_per_s": round((len(times) - 1) / (times[-1] - times[0]), 2)
                     if len(times) > 2 else None}
    print(f"[gui-overlay] a still view redrawn continuously (composite: read back, upload, one pass; quads: "
          f"the old draw): {cost}")

    # item 2: the cursor on the floor splats, by a real Shift+right-click
    clicks = result["clicks"]
    on, off = clicks["splats"], clicks["plain"]
    print(f"[gui-overlay] Shift+right-click on the floor at pixel {on['pixel']}: cursor {np.round(on['cursor'], 3)}, "
          f"{on['error_m'] * 100:.2f} cm from the floor point {np.round(on['truth'], 3)} (Show Splats off, on the "
          f"point proxy: {off['error_m'] * 100:.2f} cm, at {np.round(off['cursor'], 3)})")
    if not on["error_m"] < CURSOR_TOLERANCE_M:
        problems.append(f"the 3D cursor placed on the splat floor is {on['error_m']:.3f} m from the floor point "
                        f"(tolerance {CURSOR_TOLERANCE_M} m): {on}")
    theme = result["theme"]
    radius = 0.5 * theme["widget_unit"]
    cs, cp = shots["cursor_splats"], shots["cursor_plain"]
    n_on = _cursor_pixels(_region(cs, out), cs, on["cursor"], radius)
    n_off = _cursor_pixels(_region(cp, out), cp, on["cursor"], radius)
    print(f"[gui-overlay] the 3D cursor's red and white circle: {n_on} pixels over the splats, {n_off} without them")
    if not (n_off >= 10 and n_on >= 0.7 * n_off):
        problems.append(f"the 3D cursor is hidden by the splats ({n_on} of its circle's pixels, {n_off} without "
                        f"splats)")
    cx, cy = _project(cs, on["cursor"])
    _write(docs / "blender_overlay_cursor.png", _crop_around(_region(cs, out), cx, cy, 360, 240))
    # the selected Blob's origin dot over its splats, in the theme's active-object colour
    org = shots["origin_splats"]
    dot = _patch(_region(org, out), org, "blob", r=1)
    want = np.array(theme["object_active"][:3])
    print(f"[gui-overlay] the active Blob's origin dot over the splats: {dot.round(3)} (theme {want.round(3)})")
    if np.abs(dot - want).max() > 0.12:
        problems.append(f"the selected splat object's origin dot is hidden by the splats ({dot.round(3)} vs the "
                        f"theme's {want.round(3)})")
    # clicks select: the splats' object, a mesh in front of them, Shift adds
    sel = result["selects"]
    expected = {"wall": (["Room"], "Room"), "blob": (["Blob"], "Blob"), "occluder": (["Occluder"], "Occluder"),
                "wall_shift": (["Occluder", "Room"], "Room")}
    for tag, (names, active) in expected.items():
        got = sel.get(tag, {})
        print(f"[gui-overlay] click on {tag}: selected {got.get('selected')}, active {got.get('active')}")
        if got.get("selected") != names or got.get("active") != active:
            problems.append(f"a click on {tag} selected {got.get('selected')} (active {got.get('active')}), not "
                            f"{names} (active {active}): {got}")

    # item 6: a mesh edge over splats is as smooth as over the plain background
    rough = {}
    for tag in ("edge_alone", "edge_splats", "edge_quads"):
        shot = shots[tag]
        rough[tag] = edge_roughness(_region(shot, out), shot["edge_corners"])
    print(f"[gui-overlay] a plane's slanted edge, RMS scatter of its sub-pixel positions (pixels, columns): "
          f"alone {rough['edge_alone']}, over the splats {rough['edge_splats']}, over the splats drawn as plain "
          f"quads {rough['edge_quads']}")
    alone, splats = rough["edge_alone"][0], rough["edge_splats"][0]
    if not (np.isfinite(alone) and np.isfinite(splats) and splats <= alone + EDGE_SLACK_PX):
        problems.append(f"the mesh edge over the splats is rougher than over the plain background: {rough}")
    # for docs/img: the plane's top edge, 3x, drawn as plain quads (left, stair-stepped) and composited (right)
    es = shots["edge_splats"]
    (ax, ay), (bx, by) = sorted(sorted(es["edge_corners"], key=lambda c: -c[1])[:2])
    zoom = [np.repeat(np.repeat(_crop_around(_region(shots[t], out), 0.5 * (ax + bx), 0.5 * (ay + by), 110, 70), 3, 0),
                      3, 1) for t in ("edge_quads", "edge_splats")]
    _write(docs / "blender_overlay_edge.png", np.concatenate([zoom[0], np.ones((210, 6, 3)), zoom[1]], 1))

    # item 3: File > Import turns Show Splats on, and the imported splats are drawn
    imp = result["import"]
    print(f"[gui-overlay] File > Import: {imp}")
    if not (imp and imp["show_after"] and imp["new"] and imp["new"][0] in imp.get("drawn", [])):
        problems.append(f"after File > Import the splats are not drawn (Show Splats stays off?): {imp}")
    # item 5: Update When Moved re-bakes once after a move with G, not after Ctrl+Z, and the report is the World's
    auto = result["auto"]
    print(f"[gui-overlay] Update When Moved: parent {auto.get('parent')}, sphere {auto.get('location_0')} -> "
          f"{auto.get('location_1')} -> (Ctrl+Z) {auto.get('location_2')}; automatic bakes "
          f"{auto.get('auto_bakes_0')} -> {auto.get('auto_bakes_1')} -> {auto.get('auto_bakes_2')}; stamps "
          f"{auto.get('stamps')}, pixels as the first bake's: {auto.get('pixels_equal_bake_1')}")
    if auto.get("parent") != "Moved":
        problems.append(f"Add Probe at a selected mesh did not parent the probe to it: {auto.get('parent')}")
    if auto.get("location_1") == auto.get("location_0"):
        problems.append("G and a click in the viewport did not move the mesh")
    if auto.get("auto_bakes_1") != (auto.get("auto_bakes_0") or 0) + 1:
        problems.append(f"moving the mesh re-baked {auto.get('auto_bakes_1', 0) - auto.get('auto_bakes_0', 0)} "
                        f"times, not once")
    if auto.get("location_2") != auto.get("location_0"):
        problems.append(f"Ctrl+Z did not bring the mesh back: {auto.get('location_2')}")
    if auto.get("auto_bakes_2") != auto.get("auto_bakes_1"):
        problems.append(f"Ctrl+Z re-baked ({auto.get('auto_bakes_1')} -> {auto.get('auto_bakes_2')} automatic bakes)")
    stamps = auto.get("stamps") or {}
    if not (auto.get("report_3") == auto.get("report_1") and auto.get("pixels_equal_bake_1")
            and len(set(stamps.values())) == 1 and None not in stamps.values()):
        problems.append(f"after Ctrl+Z the report is not the one of the World in use: report {auto.get('report_3')!r}"
                        f" vs the first bake's {auto.get('report_1')!r}; stamps {stamps}; pixels as the first "
                        f"bake's: {auto.get('pixels_equal_bake_1')}")
    return problems


if __name__ == "__main__":  # analyse a kept run again: python test_gui_overlay.py build/matrix/gui-overlay/out
    import sys
    folder = Path(sys.argv[1])
    found = analyse(json.loads((folder / "shots.json").read_text()), folder, folder.parent / "docs")
    print("\n".join(found) or "all checks pass")
