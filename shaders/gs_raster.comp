#version 450
// The tile raster (gs_raster.glsl), testing every pair along every pixel's ray: for large faces.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "gs_raster.glsl"
