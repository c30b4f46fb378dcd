#version 450
// The conic raster (gs_raster.glsl) with strip masks: each strip of two pixel rows tests only the conics of the
// pairs whose footprint may reach it.
#define RASTER_CONIC 1
#define RASTER_STRIPS 1
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "gs_raster.glsl"
