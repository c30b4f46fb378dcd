#version 450
// The tile raster (gs_raster.glsl) with strip masks: each strip of two pixel rows composites only the pairs whose
// footprint may reach it. On CPU devices (render/renderer.py RASTER_STRIPS says why).
#define RASTER_STRIPS 1
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "gs_raster.glsl"
