"""Output paths: checked before any work, written under a temporary name and moved into place only when complete.

A check names the option (``--out``) and the path, says what is wrong and what to do, in one ``OutputError``.
Writability is tested by creating (and removing) a real temporary file: ``os.access`` says yes to root on a
read-only mount and knows nothing of quotas. Free space is compared with an upper estimate of what will be written.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from typing import Callable, Iterator

PARTIAL = ".partial-"  # in the name of every file or folder being written; a crash leaves it visibly unfinished


class OutputError(OSError):
    """An output path that cannot be written: the message names it and says what to do."""


def _who(path: str, option: str | None) -> str:
    return f"{option} {path}" if option else path


def _existing_ancestor(path: str) -> str:
    p = os.path.abspath(path)
    while not os.path.exists(p):
        parent = os.path.dirname(p)
        if parent == p:
            break
        p = parent
    return p


def _probe_write(folder: str, who: str) -> None:
    try:
        fd, tmp = tempfile.mkstemp(prefix=".gs-ibl-write-test-", dir=folder)
    except OSError as e:
        raise OutputError(f"{who}: cannot write in {folder} ({e.strerror or e}); choose a folder you can write to, "
                          "or change its permissions") from None
    os.close(fd)
    os.unlink(tmp)


def _check_space(folder: str, need_bytes: int, who: str) -> None:
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return  # no figure to compare with: the write itself will tell
    if need_bytes > free:
        raise OutputError(f"{who}: needs up to {need_bytes / 2**20:,.1f} MiB but {folder} has "
                          f"{free / 2**20:,.1f} MiB free; free some space or choose another disk")


def check_output_file(path: str | os.PathLike, need_bytes: int = 0, option: str | None = None,
                      extensions: tuple[str, ...] | None = None) -> str:
    """Refuse an output file path that cannot be written (a folder, a missing or read-only folder, a full disk)."""
    path = os.fspath(path)
    who = _who(path, option)
    if not path or path.endswith(os.sep):
        raise OutputError(f"{who}: is a folder name; give a file name")
    if extensions is not None and os.path.splitext(path)[1].lower() not in extensions:
        raise OutputError(f"{who}: the file name must end in {' or '.join(extensions)}")
    if os.path.isdir(path):
        raise OutputError(f"{who}: is a folder; give a file name inside it")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        what = "is a file, not a folder" if os.path.exists(parent) else "does not exist"
        raise OutputError(f"{who}: the folder {parent} {what}; create the folder first or choose another path")
    _probe_write(parent, who)
    _check_space(parent, need_bytes, who)
    return path


def check_output_dir(path: str | os.PathLike, need_bytes: int = 0, option: str | None = None) -> str:
    """Refuse an output folder that cannot be made or written (a file in the way, read-only, a full disk)."""
    path = os.fspath(path)
    who = _who(path, option)
    if not path:
        raise OutputError(f"{who}: empty folder name; give a folder")
    if os.path.exists(path) and not os.path.isdir(path):
        raise OutputError(f"{who}: is a file, not a folder; give a folder name (it is created if missing)")
    base = _existing_ancestor(path)
    if not os.path.isdir(base):
        raise OutputError(f"{who}: {base} is a file, so no folder can be made under it; choose another path")
    _probe_write(base, who)
    _check_space(base, need_bytes, who)
    return path


def partial_name(path: str) -> str:
    """A temporary name beside ``path`` keeping its extension (writers such as OpenImageIO choose by it)."""
    folder, name = os.path.split(path)
    stem, ext = os.path.splitext(name)
    return os.path.join(folder, f".{stem}{PARTIAL}{os.getpid()}{ext}")


@contextlib.contextmanager
def written_atomically(path: str | os.PathLike) -> Iterator[str]:
    """``with written_atomically(p) as tmp: write(tmp)``: ``p`` appears only complete; a failure leaves no file."""
    path = os.fspath(path)
    tmp = partial_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        remove_quietly(tmp)


def remove_quietly(path: str) -> None:
    """Remove a file or folder tree if present; errors are ignored (this runs while another error is reported)."""
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            os.unlink(path)


def _files_under(folder: str) -> list[str]:
    names = []
    for root, _dirs, files in os.walk(folder):
        rel = os.path.relpath(root, folder)
        names += [f if rel == "." else f"{rel}/{f}".replace(os.sep, "/") for f in files]
    return names


@contextlib.contextmanager
def staged_folder(out_dir: str | os.PathLike, last: str | None = None,
                  before_move: Callable[[list[str]], None] | None = None) -> Iterator[str]:
    """``with staged_folder(d) as stage: write files into stage``: they appear in ``d`` only once all are written.

    The stage is a hidden folder inside ``d`` (same disk, so each move is a rename). ``before_move(names)`` runs
    first (e.g. to remove an earlier run's files); ``last`` names the file moved last (one that vouches for the
    others). On any failure nothing new reaches ``d`` and the stage is removed.
    """
    out_dir = os.fspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    stage = os.path.join(out_dir, f".gs-ibl{PARTIAL}{os.getpid()}")
    remove_quietly(stage)
    os.makedirs(stage)
    try:
        yield stage
        names = _files_under(stage)
        if before_move is not None:
            before_move(names)
        for name in sorted(names, key=lambda n: n == last):
            final = os.path.join(out_dir, name)
            os.makedirs(os.path.dirname(final), exist_ok=True)
            os.replace(os.path.join(stage, name), final)
    finally:
        remove_quietly(stage)
