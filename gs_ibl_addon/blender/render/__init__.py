"""The splats in final renders (F12, Render Animation, ``blender -b -f N`` / ``-a``): handlers that draw them for
each frame from the scene camera, split at the meshes' depth, and the compositor nodes that put them in the picture
(docs/final-frame.md)."""
