#version 450
// The chunk partials of the *_cut rasters joined in order, FRONT and BEHIND each (gs_merge.glsl).
#extension GL_GOOGLE_include_directive : require
#define MERGE_CUT 1
layout(std430, binding = 4) readonly buffer PartialBehind { vec4 partial_behind[]; };
layout(std430, binding = 5) writeonly buffer Behind { vec4 behind[]; };
#include "gs_merge.glsl"
