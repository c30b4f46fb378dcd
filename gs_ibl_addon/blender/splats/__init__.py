"""Splat objects in Blender: importing files, reading objects (ours and Blender 5.3's), their shared GPU copy."""
