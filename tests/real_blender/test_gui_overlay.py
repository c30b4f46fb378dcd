"""The viewport overlay as a user sees it, in the real Blender 5.2 binary with its GUI (Debian sid root, Xvfb).

The built zip is installed with Blender's own installer into a fresh user directory (as test_matrix.py does), then
gui_overlay.py runs in that Blender and takes screenshots from two views (see its docstring). Checked here:
- no black vertex dots, grid or other helper drawing inside the splat region: with Show Splats on, the screenshot
  with Blender's overlays on equals the one with them off wherever the splats cover the view (overlays off, Blender
  can draw neither);
- a mesh in front of splats hides them (the Occluder cube looks as without splats);
- splats in front of a mesh hide it (the red Blob is seen where the Backdrop cube is behind it);
- while the view moves the splats are drawn at the moving resolution, and once it is still one timed redraw (no
  event) draws them at the Resolution setting.
Skipped unless the sid root has been made (scripts/blender_roots.sh ensure sid). Screenshots land in
build/matrix/gui-overlay/.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gs_ibl_addon.blender.overlay_math import MOVING_SCALE
from test_matrix import OUT, REPO, Entry, Runner, _inputs_once, _install, require_root, xvfb_shell

HERE = Path(__file__).resolve().parent
ENTRY = Entry("gui-overlay", "sid", True, gui=True)
HEADER_PX = 60  # the region's top rows hold the header's buttons, whose highlight follows the overlays toggle
COVERED = 0.95  # the splat region: pixels the room's splats cover at least this much
DIFF = 0.08  # a pixel differs when a channel differs by more than this (8-bit screenshots of the same image: 0)
MAX_DIFFERING = 5e-4  # at most this fraction of the splat region may differ (a dot per ~2000 pixels)


def _read(path: Path) -> np.ndarray:
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise AssertionError(f"cannot read screenshot {path}: {buf.geterror()}")
    return buf.get_pixels(oiio.FLOAT)[..., :3]


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


def test_gui_overlay(tmp_path_factory):
    require_root(ENTRY.root)
    zip_path = _inputs_once()["zip"]
    runner = Runner(ENTRY, tmp_path_factory.mktemp("gui"))
    for src in (zip_path, REPO / "samples" / "room.ply", HERE / "gui_overlay.py"):
        shutil.copy(src, runner.host / src.name)
    keep = OUT / ENTRY.name
    try:
        r = _install(runner, str(runner.inner / zip_path.name))
        assert r.returncode == 0, f"installing the zip failed: {r.stdout[-2000:]}\n{r.stderr[-2000:]}"
        inner = runner.inner
        r = runner.run(xvfb_shell(f"blender --python {inner / 'gui_overlay.py'} -- --out {inner / 'out'} "
                                  f"--room {inner / 'room.ply'}"), "gui_overlay")
    finally:
        shutil.rmtree(keep, ignore_errors=True)
        shutil.copytree(runner.host, keep, ignore=shutil.ignore_patterns("home", "*.ply", "*.zip", "*.blend*"))
        runner.close()
    out = keep / "out"
    assert (out / "shots.json").exists(), f"gui_overlay.py wrote no shots.json (rc {r.returncode}); see {keep}"
    result = json.loads((out / "shots.json").read_text())
    assert not result["error"], f"gui_overlay.py failed in Blender {result['blender']}:\n{result['error']}"
    # the overlay's shader (display colour, window depth) is its numpy reference's, to float precision
    check = result["shader_check"]
    assert check["colour_max_error"] < 1e-4 and check["depth_max_error"] < 1e-5, check
    shots = result["shots"]
    problems = []
    for view in ("a", "b"):
        on, clean, plain = shots[f"{view}_splats"], shots[f"{view}_clean"], shots[f"{view}_plain"]
        assert on["error"] is None, f"the overlay's draw handler failed: {on['error']}"
        img_on, img_clean, img_plain = _region(on, out), _region(clean, out), _region(plain, out)
        mask = _splat_region(on, out)
        assert mask.mean() > 0.3, f"view {view}: the splats cover only {mask.mean():.0%} of the view"
        differs = (np.abs(img_on - img_clean).max(-1) > DIFF) & mask
        dark = ((img_clean.mean(-1) - img_on.mean(-1)) > 0.2) & mask
        frac = differs.sum() / mask.sum()
        print(f"[gui-overlay] view {view}: splat region {mask.mean():.0%} of the view, {frac:.4%} of it differs "
              f"with Blender's overlays on ({dark.sum()} pixels darker, as dots or lines would be)")
        if frac > MAX_DIFFERING:
            problems.append(f"view {view}: with Blender's overlays on, {frac:.3%} of the splat region differs from "
                            f"overlays off ({dark.sum()} pixels darker): helper dots, lines or grid over the splats")
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
    draws = [(t, s) for t, s, _ms in motion["draws"]]
    moving = [s for t, s in draws if t <= motion["last_nudge"] + 0.2]
    after = [(t, s) for t, s in draws if t > motion["last_nudge"]]
    print(f"[gui-overlay] draws around the orbit (time after the last view change, scale): "
          f"{[(round(t - motion['last_nudge'], 2), s) for t, s in draws[-8:]]}")
    if MOVING_SCALE not in moving:
        problems.append(f"no coarse ({MOVING_SCALE}) draw while the view moved: {draws[-8:]}")
    if not after or after[-1][1] != motion["resolution"] or after[-1][0] < motion["last_nudge"] + 0.2:
        problems.append(f"no full-resolution redraw ({motion['resolution']}) once the view was still: {after}")
    assert not problems, f"Blender {result['blender']} (screenshots in {keep}):\n" + "\n".join(problems)
