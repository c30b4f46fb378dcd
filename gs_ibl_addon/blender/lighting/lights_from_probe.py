"""Blender sun lights for the lights a bake split off the probe (core/probe/lights.py): each bright compact region
(a sun, a lamp, a window) lights meshes as a sun with shadows of its measured width, and the World (and the
irradiance node group, which casts no shadows) keeps the rest.

A light's irradiance at normal incidence (RGB) is Blender's sun Strength (W/m^2, the largest channel) times its
Color (the irradiance over that), scaled by the probe's World strength so both parts of the light move together;
its angle is the region's (a disc of the same solid angle), so shadows soften as the source is wide. Suns, not
area lights: a probe knows where light comes from, not how far away its source is.

Every bake of a probe replaces the lights the last one made for it (found by the probe's name in a custom
property), in a "GS-IBL Lights" collection; they are plain data-blocks made inside the operator, so Undo takes
them back with the bake.
"""
from __future__ import annotations

import math

import bpy
from mathutils import Vector

COLLECTION = "GS-IBL Lights"
OWNER_KEY = "gs_ibl_probe"  # custom property on each light object: the name of the probe that made it
ENERGY_KEY = "gs_ibl_energy"  # on each light object: its Strength at the probe's Strength 1 (set_lights_strength)


def _collection(scene: bpy.types.Scene) -> bpy.types.Collection:
    coll = bpy.data.collections.get(COLLECTION)
    if coll is None:
        coll = bpy.data.collections.new(COLLECTION)
    if coll.name not in scene.collection.children:
        scene.collection.children.link(coll)
    return coll


def lights_of(probe: bpy.types.Object) -> list[bpy.types.Object]:
    """The light objects the probe's last bake made."""
    return [o for o in bpy.data.objects if o.get(OWNER_KEY) == probe.name and o.type == "LIGHT"]


def remove_lights(probe: bpy.types.Object) -> int:
    """Delete the lights the probe made (objects and their light data); returns how many."""
    found = lights_of(probe)
    for obj in found:
        data = obj.data
        bpy.data.objects.remove(obj)
        if data is not None and data.users == 0:
            bpy.data.lights.remove(data)
    return len(found)


def sync_lights(scene: bpy.types.Scene, probe: bpy.types.Object, lights: list[dict],
                strength: float = 1.0) -> list[bpy.types.Object]:
    """Replace the probe's lights by suns for ``lights`` (probe.json's "lights"); none: just remove the old."""
    remove_lights(probe)
    if not lights:
        return []
    coll = _collection(scene)
    made = []
    for k, light in enumerate(lights):
        irr = [max(0.0, float(v)) for v in light["irradiance"]]
        peak = max(irr) or 1.0
        data = bpy.data.lights.new(f"{probe.name} light {k + 1}", "SUN")
        data.energy = peak * strength
        data.color = [v / peak for v in irr]
        data.angle = math.radians(min(179.0, float(light["angle"])))
        data.use_shadow = True
        obj = bpy.data.objects.new(data.name, data)
        # A sun shines along its local -Z: point +Z at the light's direction.
        obj.rotation_euler = Vector((0.0, 0.0, 1.0)).rotation_difference(Vector(light["direction"])).to_euler()
        obj.location = probe.matrix_world.translation + 2.0 * Vector(light["direction"])  # only where it is drawn
        obj[OWNER_KEY] = probe.name
        obj[ENERGY_KEY] = peak
        coll.objects.link(obj)
        made.append(obj)
    return made


def set_lights_strength(probe: bpy.types.Object, strength: float) -> int:
    """The probe's Strength on the lights its last bake made, without a re-bake; returns how many changed (lights
    of a file saved before ENERGY_KEY existed keep theirs until the next bake)."""
    n = 0
    for obj in lights_of(probe):
        base = obj.get(ENERGY_KEY)
        if isinstance(base, float):
            obj.data.energy = base * strength
            n += 1
    return n
