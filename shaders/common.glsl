#include "constants.glsl"
// Shared by every kernel: a linear workgroup index from a 2D dispatch (large counts exceed 65535 in x).
uint linear_group() { return gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x; }
