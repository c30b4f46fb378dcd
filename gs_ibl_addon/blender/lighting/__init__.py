"""Light from the splats into Blender: probe bakes, the World, local light (per-object probes, grids, Auto)."""
