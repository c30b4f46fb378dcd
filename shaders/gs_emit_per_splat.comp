#version 450
// gs_emit.comp with one thread per splat instead of one per instance slot: for CPU devices.
#define EMIT_PER_SPLAT 1
#extension GL_GOOGLE_include_directive : require
#include "gs_emit.glsl"
