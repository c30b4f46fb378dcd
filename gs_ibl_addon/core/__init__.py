"""gs-ibl core: everything that works without Blender (numpy, Vulkan, OpenImageIO). Never imports bpy."""
