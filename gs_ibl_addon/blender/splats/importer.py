"""File > Import > Gaussian Splatting, and drag-and-drop of splat files into the viewport."""
from __future__ import annotations

import os

import bpy
import numpy as np
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, FloatProperty, StringProperty
from bpy_extras.io_utils import ImportHelper, axis_conversion

from ...core.formats import EXTENSIONS, read_scene
from ...core.formats.axes import declared_axes
from ...core.formats.spz import read_spz
from ..common.jobs import JobOperator, Step, Work
from .object import create_steps, native_splats_supported

_AXES = [(a, a, "") for a in ("X", "Y", "Z", "-X", "-Y", "-Z")]

# preset -> (forward, up) of the file, in Blender's importer terms (Blender itself: forward Y, up Z).
AXIS_PRESETS = {
    "OPENCV": ("Z", "-Y"),  # 3DGS/COLMAP training output: x right, y down, z forward
    "OPENGL": ("-Z", "Y"),  # y up, looking down -z (glTF, three.js, many web viewers)
    "BLENDER": ("Y", "Z"),  # already Z up: no rotation
}
_FILTER = ";".join("*" + e for e in EXTENSIONS)


def file_axes(preset: str, path: str, forward: str = "Z", up: str = "-Y") -> tuple[str, str]:
    """(forward, up) of the file for an Orientation preset: AUTO takes what the file declares (formats/axes.py)
    and falls back to 3DGS / OpenCV, the axes of training output."""
    if preset == "CUSTOM":
        return forward, up
    if preset == "AUTO":
        return declared_axes(path) or AXIS_PRESETS["OPENCV"]
    return AXIS_PRESETS[preset]


def import_matrix(preset: str, forward: str, up: str, scale: float, path: str = "") -> np.ndarray:
    """Object matrix that turns the coordinates of the file at ``path`` into Blender's (Z up), times a uniform
    scale."""
    forward, up = file_axes(preset, path, forward, up)
    m = np.identity(4)
    m[:3, :3] = np.array(axis_conversion(from_forward=forward, from_up=up).to_3x3()) * scale
    return m


def _is_spz(path: str) -> bool:
    return os.path.splitext(path)[1].lower() == ".spz"


class GSIBL_OT_import_splats(JobOperator, bpy.types.Operator, ImportHelper):
    """Import a 3D Gaussian Splatting file as a splat object (stored in the .blend). From the menu or a drop it
    reads beside the UI, with its progress in the status bar; Esc cancels it"""
    bl_idname = "gs_ibl.import_splats"
    bl_label = "Import Splats"  # the file browser's button: a longer label is cut ("Import Gaussian Spl...")
    bl_options = {"REGISTER", "UNDO", "PRESET"}
    job_title = "importing"

    filename_ext = ".ply"
    filter_glob: StringProperty(default=_FILTER, options={"HIDDEN"})
    files: CollectionProperty(type=bpy.types.OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})

    axis_preset: EnumProperty(
        name="Orientation",
        items=[("AUTO", "Auto", "The axes the file declares (files gs-ibl wrote for scenes it made, such as the "
                "bundled sample); otherwise 3DGS / OpenCV"),
               ("OPENCV", "3DGS / OpenCV (Y down, Z forward)",
                "Training output of 3DGS and COLMAP: rotates the scene so the file's -Y is Blender's up (+Z)"),
               ("OPENGL", "OpenGL (Y up, -Z forward)", "Y-up files: the file's +Y becomes Blender's +Z"),
               ("BLENDER", "Blender (Z up)", "No rotation"),
               ("CUSTOM", "Custom", "Choose the file's forward and up axes")],
        default="AUTO")
    axis_forward: EnumProperty(name="Forward", items=_AXES, default="Z")
    axis_up: EnumProperty(name="Up", items=_AXES, default="-Y")
    global_scale: FloatProperty(name="Scale", default=1.0, min=1e-4, max=1e4, soft_min=0.01, soft_max=100.0)
    # The SPZ spec stores RUB, but SuperSplat / splat-transform (and Niantic's ply_to_spz) store the PLY's RDF data
    # unconverted, and nothing in a v2/v3 file says which: such files come in upside down unless told.
    spz_axes: EnumProperty(
        name="SPZ Axes",
        items=[("RUB", "RUB (spec)", "As the SPZ specification says: x right, y up, z back (a version-4 file's "
                "coordinate-system record, if present, is used instead)"),
               ("RDF", "RDF (as exported by SuperSplat)", "Data stored unconverted from a 3DGS PLY: x right, y down, "
                "z forward (SuperSplat, splat-transform, Niantic's ply_to_spz); use when an .spz comes in upside "
                "down")],
        default="RUB")
    native: BoolProperty(
        name="Blender Splats", default=True,
        description="Blender 5.3 and later: make a Gaussian-splat Point Cloud that Blender draws in the viewport and "
                    "renders in EEVEE and Cycles itself; off: a mesh shown by the GS-IBL overlay and never rendered "
                    "(what older Blenders always get)")
    show_splats: BoolProperty(name="Show Splats", default=True,
                              description="Turn on the GS-IBL overlay so the imported splats are drawn in the "
                                          "viewport (mesh objects only; Blender draws its own splats itself)")
    show_proxy: BoolProperty(name="Point Proxy", default=True,
                             description="Show a random subset of the splats as coloured points in the viewport "
                                         "(mesh objects only)")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "axis_preset")
        if self.axis_preset == "CUSTOM":
            layout.prop(self, "axis_forward")
            layout.prop(self, "axis_up")
        layout.prop(self, "global_scale")
        if any(_is_spz(p) for p in self._paths()):
            layout.prop(self, "spz_axes")
        if native_splats_supported():
            layout.prop(self, "native")
        if not self._native():
            layout.prop(self, "show_splats")
            layout.prop(self, "show_proxy")

    def _native(self) -> bool:
        return self.native and native_splats_supported()

    def _paths(self) -> list[str]:
        names = [f.name for f in self.files if f.name]
        if names and self.directory:
            return [os.path.join(self.directory, n) for n in names]
        return [self.filepath]

    def make_job(self, context):
        if self.axis_preset == "CUSTOM" and self.axis_forward.lstrip("-") == self.axis_up.lstrip("-"):
            raise ValueError("Forward and Up must be different axes")
        paths = self._paths()
        matrices = [import_matrix(self.axis_preset, self.axis_forward, self.axis_up, self.global_scale, p)
                    for p in paths]
        return _import_steps(paths, matrices, "RDF" if self.spz_axes == "RDF" else None, self._native(),
                             self.show_proxy, self.show_splats)

    def finished(self, context, result):
        for line in result:
            self.report({"INFO"}, line)
        return {"FINISHED"}

    # set by invoke (the file browser, a drop): execute() then runs the import beside the UI; scripts, which call
    # execute() directly, get their objects at once
    from_ui: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    def invoke(self, context, event):
        self.from_ui = True
        if self.filepath or (self.directory and len(self.files)):
            # Dropped on the viewport: the file is known, ask only for the options (then execute() runs: the
            # popup's OK button calls it, not a modal run; the read still goes beside the UI, see execute)
            return self.invoke_popup(context)
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        # The file browser's Import button and the drop popup's OK call execute(): from a window it starts the
        # modal run (invoke of JobOperator) so a 3M-splat file reads beside the UI; scripts and blender -b run now.
        if self.from_ui and not bpy.app.background and context.window is not None and not self.options.is_repeat:
            return JobOperator.invoke(self, context, None)
        return JobOperator.execute(self, context)


def _read_file(path: str, spz_coordinates: str | None, progress=None):
    """The worker's part of an import: one file read and checked (core; no bpy)."""
    if progress is not None:
        progress(f"reading {os.path.basename(path)}", 0.0)
    try:
        if _is_spz(path):
            # RUB: None, so that a version-4 coordinate-system record still wins over the spec's default
            return read_spz(path, coordinates=spz_coordinates)
        return read_scene(path)
    except MemoryError:
        raise MemoryError(f"{path}: not enough memory to read this file: close other programs or import a smaller "
                          "or compressed version (.sog, .spz, compressed .ply)") from None


def _import_steps(paths: list[str], matrices: list[np.ndarray], spz_coordinates: str | None, native: bool,
                  proxy: bool, show_splats: bool):
    """The import as a job (blender/jobs.py): every file read first by a worker (a bad file cancels the whole
    import before anything is made), then the objects made on the main thread. Its result: the report lines."""
    scenes = []
    for i, path in enumerate(paths):
        span = (0.8 * i / len(paths), 0.8 * (i + 1) / len(paths))
        scenes.append((yield Work(_read_file, path, spz_coordinates, span=span, uses_gpu=False)))
    lines, made = [], []
    try:
        for (path, scene), matrix in zip(zip(paths, scenes), matrices):
            yield Step(f"making the splat object of {os.path.basename(path)} ({scene.count:,} splats)", 0.8)
            name = os.path.splitext(os.path.basename(path))[0] or "Splats"
            obj = yield from create_steps(bpy.context, scene, name, matrix, proxy=proxy, native=native)
            made.append(obj.name)
            repaired = ", ".join(f"{k}: {v}" for k, v in scene.repairs.items())
            kind = "Blender splats" if native else "a mesh for the GS-IBL overlay"
            lines.append(f"Imported {scene.count:,} splats (SH degree {scene.sh_degree}) as {obj.name!r} ({kind})"
                         + (f"; repaired {repaired}" if repaired else ""))
    except BaseException:  # a failure or a cancel while making the second file's object: none stays
        for name in made:
            obj = bpy.data.objects.get(name)
            if obj is not None:
                data = obj.data
                bpy.data.objects.remove(obj)
                (bpy.data.pointclouds if native else bpy.data.meshes).remove(data)
        bpy.context.view_layer.update()  # its selection would list the removed objects as None until synced
        raise
    if scenes and not native and show_splats:
        bpy.context.scene.gs_ibl_overlay.show = True  # seen at once, not as a grey pin-cushion of proxy points
    return lines


class GSIBL_FH_splats(bpy.types.FileHandler):
    bl_idname = "GSIBL_FH_splats"
    bl_label = "Gaussian Splatting"
    bl_import_operator = GSIBL_OT_import_splats.bl_idname
    # not .json (a SOG folder's meta.json, choosable in File > Import): a handler for every dropped .json is too broad
    bl_file_extensions = ";".join(e for e in EXTENSIONS if e != ".json")

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type in {"VIEW_3D", "OUTLINER"}


def menu_import(self, context):
    self.layout.operator(GSIBL_OT_import_splats.bl_idname, text="Gaussian Splatting (" +
                         ", ".join(EXTENSIONS) + ")")


CLASSES = (GSIBL_OT_import_splats, GSIBL_FH_splats)
MENUS = ((bpy.types.TOPBAR_MT_file_import, menu_import),)
