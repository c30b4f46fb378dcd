"""The splats in the 3D Viewport: the overlay drawn by our renderer, and clicking on splats."""
