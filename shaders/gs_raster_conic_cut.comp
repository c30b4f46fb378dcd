#version 450
// gs_raster_conic.comp with a depth cut: FRONT and BEHIND layers (gs_raster.glsl RASTER_CUT), for camera frames.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#define RASTER_CUT 1
#define RASTER_CONIC 1
layout(std430, binding = 7) readonly buffer Cut { float cuts[]; };
layout(std430, binding = 8) writeonly buffer Behind { vec4 behind[]; };
#include "gs_raster.glsl"
