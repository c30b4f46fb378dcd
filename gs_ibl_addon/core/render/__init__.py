"""The splat renderer: cameras (a pinhole view, or the six faces of a probe) -> float RGBA images."""
