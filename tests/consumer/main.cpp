// Decodes every tile of a container with the installed engine and checks the vertex counts: each tile's
// against the index, their sum against the header and, when given, against the expected total.
//   consumer FILE.spz [EXPECTED_VERTICES]
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include "engine/container/container.h"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: consumer FILE.spz [EXPECTED_VERTICES]\n");
    return 1;
  }
  const std::string path = argv[1];
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "cannot open %s\n", path.c_str());
    return 1;
  }
  const std::vector<uint8_t> file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());

  auto container = scanpress::parseContainer(file, path);
  if (!container.isOk()) {
    std::fprintf(stderr, "%s\n", container.status().toString().c_str());
    return 2;
  }
  uint64_t vertices = 0, faces = 0;
  for (const scanpress::TileEntry& e : container->tiles) {
    auto payload = scanpress::parseTileChunk(std::span(file).subspan(e.offset, e.chunk_bytes), e, path);
    if (!payload.isOk()) {
      std::fprintf(stderr, "%s\n", payload.status().toString().c_str());
      return 2;
    }
    auto mesh = scanpress::decodeTilePayload(container->header, e, *payload, path);
    if (!mesh.isOk()) {
      std::fprintf(stderr, "%s\n", mesh.status().toString().c_str());
      return 2;
    }
    if (mesh->positions.size() != e.vertices) {
      std::fprintf(stderr, "tile %u: %zu vertices decoded, %u in the index\n", e.tile_id, mesh->positions.size(),
                   e.vertices);
      return 3;
    }
    vertices += mesh->positions.size();
    faces += mesh->triangles.size();
  }
  std::printf("%s: %zu tiles, %llu vertices, %llu faces\n", path.c_str(), container->tiles.size(),
              static_cast<unsigned long long>(vertices), static_cast<unsigned long long>(faces));
  if (vertices != container->header.vertices || faces != container->header.faces) {
    std::fprintf(stderr, "decoded totals differ from the header (%llu vertices, %llu faces)\n",
                 static_cast<unsigned long long>(container->header.vertices),
                 static_cast<unsigned long long>(container->header.faces));
    return 3;
  }
  if (argc > 2 && vertices != std::strtoull(argv[2], nullptr, 10)) {
    std::fprintf(stderr, "expected %s vertices\n", argv[2]);
    return 3;
  }
  return 0;
}
