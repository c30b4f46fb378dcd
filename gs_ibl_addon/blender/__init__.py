"""The Blender side of gs-ibl: the only package that imports bpy. Thin: it calls core and never re-implements it."""
