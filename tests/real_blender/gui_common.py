"""What the GUI checks (gui_overlay.py, gui_jobs.py) share, run inside a real Blender with its window: the installed
extension's package, the 3D View, real keys and clicks through xdotool, and the timer that runs a check's steps
one after the other while the window draws between them."""
from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import traceback
from typing import Callable, Iterator

import bpy


ARGS = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []  # the script's own, after Blender's "--"


def arg(name: str, default=None):
    """The value after ``name`` among the script's arguments (``blender --python script.py -- --out DIR``)."""
    return ARGS[ARGS.index(name) + 1] if name in ARGS else default


def write_result(path: str, result: dict, error: str | None) -> None:
    """The check's JSON (with Blender's and Python's versions and the error), error.txt beside it on failure; then
    Blender quits."""
    with open(path, "w") as f:
        json.dump({**result, "blender": bpy.app.version_string, "python": sys.version.split()[0], "error": error},
                  f, indent=1)
    if error:
        with open(os.path.join(os.path.dirname(path), "error.txt"), "w") as f:
            f.write(error)
    bpy.ops.wm.quit_blender()


def start(steps_of: Callable[[str], Iterator[tuple[float, Callable[[], None]]]],
          finish: Callable[[str | None], None], src: str | None = None) -> None:
    """Find the extension's package, then run_steps(steps_of(package), finish); a failure to find it finishes."""
    try:
        pkg = package(src)
    except Exception:  # noqa: BLE001
        finish(traceback.format_exc())
        return
    run_steps(steps_of(pkg), finish)


def package(src: str | None = None) -> str:
    """The extension's package: the installed one (bl_ext.<repo>.gs_ibl) or, with ``src``, a checkout's
    (registered directly: for working on a check before a zip exists)."""
    if src:
        sys.path.insert(0, src)
        import gs_ibl_addon
        gs_ibl_addon.register()
        return "gs_ibl_addon"
    names = [m for m in bpy.context.preferences.addons.keys() if m.endswith("gs_ibl")]
    if not names:
        raise RuntimeError("the gs_ibl extension is not enabled in this Blender "
                           f"(enabled: {sorted(bpy.context.preferences.addons.keys())})")
    return names[0]


def mod(pkg: str, name: str):
    return importlib.import_module(f"{pkg}.{name}")


def view3d():
    """(window, area, space, region) of the first 3D Viewport."""
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                region = next(r for r in area.regions if r.type == "WINDOW")
                return window, area, area.spaces.active, region
    raise RuntimeError("no 3D Viewport in the window")


_xwin: list[str] = []


def focus() -> None:
    """Give Blender's X window the keyboard focus (xdotool's keys go to the focused window)."""
    if not _xwin:
        r = subprocess.run(["xdotool", "search", "--name", "Blender"], capture_output=True, text=True)
        ids = r.stdout.split()
        if not ids:
            raise RuntimeError(f"xdotool finds no Blender window: {r.stdout} {r.stderr}")
        _xwin.append(ids[-1])
    subprocess.run(["xdotool", "windowfocus", "--sync", _xwin[0]], check=True)


def xdo(*args) -> None:
    subprocess.run(["xdotool", *map(str, args)], check=True)


def run_steps(steps: Iterator[tuple[float, Callable[[], None]]], finish: Callable[[str | None], None]) -> None:
    """Run ``steps`` ((seconds to wait before it, action), ...) from a timer, so Blender draws between them; then
    ``finish(None)``, or ``finish(traceback)`` at the first failure."""
    pending: list = []
    busy: list = []

    def tick():
        # run the action that was waiting, then wait as long as the next one asks before running it
        if busy:  # a blocking render lets Blender run timers meanwhile: not this one again
            return 1.0
        if pending:
            busy.append(True)
            try:
                pending.pop()()
            except BaseException:  # noqa: BLE001  (a StopIteration inside an action is a failure too)
                finish(traceback.format_exc())
                return None
            finally:
                busy.clear()
        try:
            delay, action = next(steps)
        except StopIteration:
            finish(None)
            return None
        except Exception:  # noqa: BLE001
            finish(traceback.format_exc())
            return None
        pending.append(action)
        return delay

    bpy.context.preferences.view.show_splash = False  # a fresh user directory would open on the splash
    bpy.app.timers.register(tick, first_interval=1.0)
