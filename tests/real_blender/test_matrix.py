"""The real-Blender matrix: the built zip, installed by Blender's own extension machinery into a fresh user
directory, then tests/real_blender/scenario.py run inside that Blender (import, probe, bake, EEVEE and Cycles
frames, save and reload).

Each entry is skipped unless its Blender has been made (`scripts/blender_roots.sh ensure ...`, which
`scripts/test_real_blender.sh` does), so `pytest tests` on a fresh machine stays fast. Results, logs, renders and
screenshots of each entry land in build/matrix/<entry>/.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blender_scene as bs  # noqa: E402 (the scenes and Blender set-up shared with the benchmarks)

REPO = Path(__file__).resolve().parents[2]
ROOTS_SH = REPO / "scripts" / "blender_roots.sh"
OUT = REPO / "build" / "matrix"
HERE = Path(__file__).resolve().parent
CAPTURE = REPO / "tests" / "data" / "guitar.compressed.ply"
CAPTURE_COUNT = 90854  # tests/data/README.md
TIMEOUT_S = 900
STALE_S = 3 * 3600  # a run's folder in a root older than this was left by a killed run
RESULT_TAG = "GSIBL-MATRIX-RESULT "  # scenario.py's
PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"


@dataclass(frozen=True)
class Entry:
    name: str
    root: str  # the blender_roots.sh entry it needs
    chroot: bool  # runs inside that root (else: a venv on this machine)
    python: str | None = None  # the bpy module's Python; None: the Blender binary
    gui: bool = False


ENTRIES = [
    Entry("bpy-4.2", "bpy42", False, python="bin/python"),
    Entry("bpy-5.0", "bpy50", False, python="bin/python"),
    Entry("bpy-5.3", "trixie", True, python="/opt/bpy53/bin/python"),
    Entry("blender-5.2", "sid", True),
    Entry("blender-5.2-gui", "sid", True, gui=True),
]


def _roots(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(ROOTS_SH), *args], capture_output=True, text=True, **kw)


def require_root(root: str) -> None:
    """Skip (or fail) a check that runs in a real Blender's root: every such check runs once in CI, in
    scripts/test_real_blender.sh, which requires the roots; the fast suite before it skips them."""
    if os.environ.get("GS_IBL_SKIP_MATRIX"):
        pytest.skip("GS_IBL_SKIP_MATRIX is set (CI runs the real-Blender checks in scripts/test_real_blender.sh)")
    if not _ready(root):
        if os.environ.get("GS_IBL_REQUIRE_MATRIX"):
            pytest.fail(f"{root} is not made, and scripts/test_real_blender.sh requires every root")
        pytest.skip(f"{root} not made: scripts/blender_roots.sh ensure {root} (or bash scripts/test_real_blender.sh)")


def _ready(root: str) -> bool:
    return _roots("ready", root).returncode == 0


CONVERTED = ("sog", "glb", "ksplat")  # formats Blender cannot read, written by our convert (SOG: WebP in Blender)


_ZIP: list[Path] = []


def built_zip() -> Path:
    """The extension's zip, built once per test session: every entry and every check installs the same file."""
    if not _ZIP:
        OUT.mkdir(parents=True, exist_ok=True)
        zip_path = OUT / "gs_ibl.zip"
        subprocess.run([sys.executable, "scripts/build_extension.py", "--output", str(zip_path)], cwd=REPO,
                       check=True, capture_output=True, text=True)
        _ZIP.append(zip_path)
    return _ZIP[0]


def _build_inputs() -> dict[str, Path]:
    """The zip and the splat files every entry imports (SPZ and plain PLY made by our CLI)."""
    zip_path = built_zip()
    files = {"room": REPO / "samples" / "room.ply", "capture": CAPTURE,
             "spz": OUT / "inputs" / "guitar.spz", "ply": OUT / "inputs" / "guitar.ply",
             "spz4": OUT / "inputs" / "guitar.v4.spz", **{k: OUT / "inputs" / f"guitar.{k}" for k in CONVERTED}}
    files["spz"].parent.mkdir(exist_ok=True)
    for key in ("spz", "ply", "spz4", *CONVERTED):
        files[key].unlink(missing_ok=True)  # the CLI never overwrites
    for key in ("spz", "ply", *CONVERTED):
        subprocess.run([sys.executable, "-m", "gs_ibl_addon", "convert", str(CAPTURE), str(files[key])], cwd=REPO,
                       check=True, capture_output=True, text=True)
    # SPZ version 4 (ZSTD streams: the reader needs zstandard, which not every Blender ships); the CLI writes 3
    subprocess.run([sys.executable, "-c", "import sys; from gs_ibl_addon.core.formats import read_scene; "
                    "from gs_ibl_addon.core.formats.spz import write_spz; "
                    "write_spz(sys.argv[2], read_scene(sys.argv[1]), version=4)", str(CAPTURE), str(files["spz4"])],
                   cwd=REPO, check=True, capture_output=True, text=True)
    return {"zip": zip_path, **files}


def _free_display() -> int:
    """An X display number nobody listens on (abstract sockets are shared with the roots)."""
    used = Path("/proc/net/unix").read_text()
    return next(n for n in range(90, 200) if f"/tmp/.X11-unix/X{n}" not in used
                and not Path(f"/tmp/.X{n}-lock").exists())


class Runner:
    """Runs commands for one entry: on this machine, or in its root where /tmp is `path ROOT`/tmp here."""

    def __init__(self, entry: Entry, host_tmp: Path):
        self.entry = entry
        if entry.chroot:
            # a folder of its own per run: two runs of one entry (a CI run beside someone's) never share one
            parent = Path(_roots("path", entry.root, check=True).stdout.strip()) / "tmp" / "gs-ibl-matrix"
            parent.mkdir(parents=True, exist_ok=True)
            for old in parent.iterdir():  # what runs that were killed left behind
                if time.time() - old.stat().st_mtime > STALE_S:
                    shutil.rmtree(old, ignore_errors=True)
            self.host = Path(tempfile.mkdtemp(prefix=f"{entry.name}-", dir=parent))
            self.inner = Path("/tmp/gs-ibl-matrix") / self.host.name
        else:
            self.host = self.inner = host_tmp / entry.name
            self.venv = Path(_roots("path", entry.root, check=True).stdout.strip())
            shutil.rmtree(self.host, ignore_errors=True)
        (self.host / "home").mkdir(parents=True)

    def close(self) -> None:
        """Delete the run's folder (in a root it would outlive pytest's temporary folders)."""
        shutil.rmtree(self.host, ignore_errors=True)

    def env(self) -> dict[str, str]:
        # a fresh user directory: Blender's config, scripts and extensions all live under this HOME
        return {"PATH": PATH, "HOME": str(self.inner / "home"), "LANG": "C.UTF-8"}

    def run(self, argv: list[str], log: str) -> subprocess.CompletedProcess:
        if self.entry.chroot:
            env_args = [f"{k}={v}" for k, v in self.env().items()]
            cmd = ["bash", str(ROOTS_SH), "chroot", self.entry.root, "env", "-C", str(self.inner), *env_args, *argv]
            kw = {}
        else:
            cmd, kw = argv, {"env": self.env(), "cwd": self.host}  # cwd: this repository is not importable
        t0 = time.perf_counter()
        # a session of its own: on a timeout the whole group goes (Blender inside a chroot, Xvfb)
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                             **kw)
        try:
            out, err = p.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            out, err = p.communicate()
            err += f"\n[matrix] killed after {TIMEOUT_S} s"
        r = subprocess.CompletedProcess(cmd, p.returncode, out, err)
        (self.host / f"{log}.log").write_text(f"$ {' '.join(cmd)}\n[rc {r.returncode}, "
                                              f"{time.perf_counter() - t0:.1f} s]\n{r.stdout}\n--- stderr\n{r.stderr}")
        return r

    def python(self) -> str:
        p = self.entry.python
        return p if self.entry.chroot else str(self.venv / p)


_INSTALL_BPY = """\
import sys
import bpy
import addon_utils  # importable once bpy is
r = bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
bpy.ops.wm.save_userpref()
ok = r == {"FINISHED"} and addon_utils.check("bl_ext.user_default.gs_ibl")[1]
print("installed and enabled" if ok else f"NOT enabled: {r}")
sys.exit(0 if ok else 1)
"""


def _install(runner: Runner, zip_inner: str) -> subprocess.CompletedProcess:
    """Blender's own installer: the binary's `extension install-file`, or the same operator in the bpy module."""
    if runner.entry.python is None:
        return runner.run(["blender", "--command", "extension", "install-file", "-r", "user_default", "-e",
                           zip_inner], "install")
    (runner.host / "install.py").write_text(_INSTALL_BPY)
    return runner.run([runner.python(), str(runner.inner / "install.py"), zip_inner], "install")


def run_script(runner: Runner, script: Path, args: dict, tag: str, log: str) -> dict:
    """Install the built zip with Blender's installer in ``runner``'s bpy module, run ``script`` there on
    args.json (``args``) with blender_scene.py beside it (the scenes and set-up it imports), and return the JSON
    of its stdout line starting with ``tag``."""
    zip_path = built_zip()
    shutil.copy(zip_path, runner.host / zip_path.name)
    shutil.copy(script, runner.host / script.name)
    shutil.copy(HERE / "blender_scene.py", runner.host / "blender_scene.py")
    (runner.host / "args.json").write_text(json.dumps(args, indent=1))
    assert _install(runner, str(runner.inner / zip_path.name)).returncode == 0, \
        (runner.host / "install.log").read_text()[-2000:]
    r = runner.run([runner.python(), str(runner.inner / script.name), str(runner.inner / "args.json")], log)
    line = next((x for x in r.stdout.splitlines() if x.startswith(tag + " ")), None)
    assert line, f"no result (rc {r.returncode}): {r.stdout[-2000:]}\n{r.stderr[-3000:]}"
    return json.loads(line.split(" ", 1)[1])


def _scenario_cmd(runner: Runner, args_inner: str) -> list[str]:
    script = str(runner.inner / "scenario.py")
    if runner.entry.python is not None:
        return [runner.python(), script, args_inner]
    if not runner.entry.gui:
        return ["blender", "-b", "--python", script, "--", args_inner]
    return xvfb_shell(f"blender --python {script} -- {args_inner}")


def run_gui_script(entry: Entry, tmp: Path, script: str, result_name: str, args: str = "",
                   inputs: tuple[Path, ...] = (), prepare=None) -> tuple[dict, Path, Path]:
    """A GUI check's run: the built zip installed by Blender's installer in ``entry``'s root, then
    ``blender --python SCRIPT -- --out OUT ARGS`` under Xvfb (``script`` and gui_common.py from this folder,
    ``inputs`` copied beside them; ``prepare(host_folder)`` may write more). What the run left is kept in
    build/matrix/<entry>/ (no user dir, splat files, zips or .blend files). Returns (the script's ``result_name``
    JSON, its out folder, the kept folder); fails when the script wrote none or reported an error."""
    require_root(entry.root)
    zip_path = _inputs_once()["zip"]
    runner = Runner(entry, tmp)
    here = Path(__file__).resolve().parent
    for src in (zip_path, here / script, here / "gui_common.py", *inputs):
        shutil.copy(src, runner.host / Path(src).name)
    if prepare is not None:
        prepare(runner.host)
    keep = OUT / entry.name
    try:
        r = _install(runner, str(runner.inner / zip_path.name))
        assert r.returncode == 0, f"installing the zip failed: {r.stdout[-2000:]}\n{r.stderr[-2000:]}"
        inner = runner.inner
        r = runner.run(xvfb_shell(f"blender --python {inner / script} -- --out {inner / 'out'} "
                                  + args.format(inner=inner)), Path(script).stem)
    finally:
        shutil.rmtree(keep, ignore_errors=True)
        shutil.copytree(runner.host, keep, ignore=shutil.ignore_patterns("home", "*.ply", "*.zip", "*.blend*"))
        runner.close()
    out = keep / "out"
    assert (out / result_name).exists(), f"{script} wrote no {result_name} (rc {r.returncode}); see {keep}"
    result = json.loads((out / result_name).read_text())
    assert not result["error"], f"{script} failed in Blender {result['blender']}:\n{result['error']}"
    return result, out, keep


def xvfb_shell(command: str, screen: str = "1600x1000x24") -> list[str]:
    """`sh -c` running COMMAND with DISPLAY set to a new Xvfb, which picks a free display itself (-displayfd) and
    is stopped afterwards; the exit status is COMMAND's."""
    return ["sh", "-c", f"Xvfb -displayfd 3 -screen 0 {screen} -nolisten tcp 3>display 2>xvfb.log & x=$!; "
            "i=0; while [ ! -s display ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i+1)); done; "
            f"DISPLAY=:$(cat display) {command}; rc=$?; kill $x; exit $rc"]


@pytest.mark.parametrize("entry", [pytest.param(e, id=e.name) for e in ENTRIES])
def test_entry(entry: Entry, tmp_path_factory):
    require_root(entry.root)
    files = _inputs_once()
    runner = Runner(entry, tmp_path_factory.mktemp("matrix"))
    inner = {}
    for key, path in files.items():
        shutil.copy(path, runner.host / path.name)
        inner[key] = str(runner.inner / path.name)
    for name in ("scenario.py", "blender_scene.py"):
        shutil.copy(HERE / name, runner.host / name)
    args = {"entry": entry.name, "work": str(runner.inner), "user_dir": str(runner.inner / "home"),
            "result": str(runner.inner / "result.json"),
            "files": {k: inner[k] for k in ("room", "capture", "spz", "ply", "spz4", *CONVERTED)},
            "capture_count": CAPTURE_COUNT,
            "probe_in_room": list(bs.ROOM_SPHERE["centre"]), "face_size": 64, "albedo": bs.ALBEDO, "size": 48,
            "eevee_samples": 4, "cycles_samples": 16, "gui_wait_s": 10.0}
    (runner.host / "args.json").write_text(json.dumps(args, indent=1))

    t0 = time.perf_counter()
    r = _install(runner, inner["zip"])
    t_install = time.perf_counter() - t0
    ok_install = r.returncode == 0
    t0 = time.perf_counter()
    r = runner.run(_scenario_cmd(runner, str(runner.inner / "args.json")), "scenario")
    t_scenario = time.perf_counter() - t0
    keep = OUT / entry.name
    shutil.rmtree(keep, ignore_errors=True)
    shutil.copytree(runner.host, keep, ignore=shutil.ignore_patterns("home", "*.ply", "*.spz", "*.zip", "*.blend*", "*.sog",
                                                                  "*.glb", "*.ksplat"))
    result_file = keep / "result.json"
    runner.close()
    assert result_file.exists(), f"{entry.name}: the scenario wrote no result (rc {r.returncode}); see {keep}"
    result = json.loads(result_file.read_text())
    # the scenario's own result line quotes the tracebacks it caught: only what Blender printed counts here
    console = "\n".join(line for line in (r.stdout + r.stderr).splitlines() if not line.startswith(RESULT_TAG))
    tracebacks = [console[i:i + 1500] for i in range(len(console)) if console.startswith("Traceback", i)]
    result["checks"].insert(0, {"name": "install with Blender's installer", "ok": ok_install,
                                "detail": (keep / "install.log").read_text()[-3000:]})
    result["checks"].append({"name": "no tracebacks in Blender's console", "ok": not tracebacks,
                             "detail": "\n...\n".join(tracebacks[:3])})
    result["timings_s"].update(install=round(t_install, 1), scenario=round(t_scenario, 1))
    (keep / "result.json").write_text(json.dumps(result, indent=1))
    print(f"\n[matrix] {entry.name}: {result['info'].get('blender')} Python {result['info'].get('python')}, "
          f"install {t_install:.0f} s, scenario {t_scenario:.0f} s; timings {result['timings_s']}")
    failed = [c for c in result["checks"] if not c["ok"]]
    assert not failed, f"{entry.name} ({keep}): " + "\n\n".join(f"{c['name']}: {c['detail'][-1500:]}" for c in failed)


_INPUTS: dict = {}


def _inputs_once() -> dict[str, Path]:
    """inputs() once per session, built only when some entry runs (a skipped matrix builds nothing)."""
    if not _INPUTS:
        _INPUTS.update(_build_inputs())
    return _INPUTS
