// Texture coordinates (issue 22 part 1): a pair of scalar channels, by PLY's conventions. They travel as scalar
// channels do (kept bit for bit by every codec that carries scalars; FORMAT.md "Scalar channels"), so a container
// needs nothing of its own for them; the OBJ and glTF writers find the pair and write it as `vt` and TEXCOORD_0.
//
// A vertex has one pair. Where a file gives a vertex's corners different texture coordinates (an OBJ `vt` seam, a
// PLY face's `texcoord` list), the reader splits the vertex into wedges: one vertex per distinct coordinate, at the
// same position (WedgePlan in mesh_reader.h); the OBJ writer joins the wedges' positions again.
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "engine/mesh.h"

namespace scanpress {

// The channel names the readers give OBJ `vt` and PLY face `texcoord` lists (float32).
inline constexpr const char* kTexcoordU = "u";
inline constexpr const char* kTexcoordV = "v";

// TexcoordChannels, findTexcoords (the pair's names) and floatChannelValue are in engine/mesh.h: codecs predict the
// pair, and quantization snaps it.

// Whether a mesh file at `path` writes each of `channels`: all of them for PLY, the texture coordinates for OBJ (of a
// mesh with triangles: `vt` are named by faces) and glTF (.glb, .gltf), none for STL and OFF. What is not written is
// reported dropped by the caller.
std::vector<bool> channelsWritten(const std::string& path, std::span<const ScalarChannel> channels,
                                  bool triangles = true);

}  // namespace scanpress
