#version 450
// The tile raster (gs_raster.glsl) with each pair's footprint conic tested first: for faces up to
// CONIC_MAX_FACE (render/renderer.py says why).
#define RASTER_CONIC 1
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "gs_raster.glsl"
