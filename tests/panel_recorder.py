"""A stand-in for Blender's UILayout that records what a panel's draw function lays out, for the panel tests
(test_blender_panel.py, test_blender_panel_render.py, test_blender_render.py)."""
from __future__ import annotations

from types import SimpleNamespace


class Rows:
    """Records what a draw function lays out: each prop with the text it would show and the row it is in (a row
    holds the props drawn into it; a column gives each prop a row of its own)."""

    def __init__(self, rec: dict, row: bool = False):
        self.rec, self.is_row = rec, row
        self.ident = len(rec.setdefault("containers", [])) if row else None
        if row:
            rec["containers"].append([])

    def _slot(self) -> list:
        if self.is_row:
            return self.rec["containers"][self.ident]
        self.rec.setdefault("containers", []).append([])
        return self.rec["containers"][-1]

    def prop(self, data, name, text=None, **_kw):
        self._slot().append(name)
        self.rec.setdefault("props", []).append((name, text if text is not None else
                                                 data.bl_rna.properties[name].name))

    def label(self, text="", icon="NONE", **_kw):
        self.rec.setdefault("labels", []).append((text, icon))

    def row(self, *_a, **_kw):
        return Rows(self.rec, row=True)

    def column(self, *_a, **_kw):
        return Rows(self.rec)

    box = split = column_flow = grid_flow = column

    def __getattr__(self, _name):
        return lambda *a, **kw: Rows(self.rec)


def draw_panel(context=None) -> dict:
    """The sidebar's GS-IBL panel drawn into a Rows: {"labels": [(text, icon)], "props": [(name, text shown)],
    "containers": [[prop names of a row]]}."""
    import bpy
    from gs_ibl_addon.blender.ui.panel import GSIBL_PT_panel
    rec: dict = {}
    GSIBL_PT_panel.draw(SimpleNamespace(layout=Rows(rec)), context or bpy.context)
    return rec
