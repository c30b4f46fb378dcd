#version 450
// gs_emit.glsl with one thread per instance slot.
#extension GL_GOOGLE_include_directive : require
#include "gs_emit.glsl"
