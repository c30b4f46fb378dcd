"""What every other part of the Blender side stands on: version differences, our datablocks' marks, jobs."""
