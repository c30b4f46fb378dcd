#version 450
// The chunk partials of the raster joined in order (gs_merge.glsl).
#extension GL_GOOGLE_include_directive : require
#include "gs_merge.glsl"
