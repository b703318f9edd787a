// Simple generated meshes: used by `synth` as a built-in base and by tests as analytic references.
#pragma once

#include "engine/mesh.h"

namespace scanpress {

// The icosahedron inscribed in the unit sphere, each triangle split in four `levels` times with the new vertices
// pushed onto the sphere (20 * 4^levels triangles, consistently oriented outwards).
Mesh icosphere(int levels);

// A torus around the z axis: `rings` x `sides` grid of vertices on the tube of radius `minor` whose centre circle
// has radius `major` (2 * rings * sides triangles, consistently oriented outwards).
Mesh torus(int rings, int sides, double major, double minor);

}  // namespace scanpress
