"""Adding and removing the extension's functions in bpy.app.handlers lists, by (list name, function) tables.

Adding twice is a no-op (a re-registered extension or a reloaded file keeps one entry); removing takes every entry of
the function, so a list is left as the extension found it."""
from __future__ import annotations

from collections.abc import Callable, Iterable

import bpy

Handlers = Iterable[tuple[str, Callable]]


def add(table: Handlers) -> None:
    for name, fn in table:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def remove(table: Handlers) -> None:
    for name, fn in table:
        handlers = getattr(bpy.app.handlers, name)
        while fn in handlers:
            handlers.remove(fn)
