// Independent checks of a Simplification (engine/simplify/simplify.h), shared by the engine tests and the
// real-scan tests: a replay of the collapses pass by pass that also checks the passes' closed one-rings are
// disjoint, and mesh validity checks.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "engine/simplify/simplify.h"

namespace scanpress::testing {

// Replays `s.collapses` on `input` as the header defines a collapse, pass by pass; fails the test if two collapses
// of a pass have overlapping closed one-rings (in the mesh at the pass's start) or if a collapse is not an edge.
inline QuantizedMesh replayCollapses(const QuantizedMesh& input, const Simplification& s) {
  QuantizedMesh m = input;
  std::vector<uint8_t> alive(m.triangles.size(), 1);
  size_t begin = 0;
  EXPECT_TRUE(s.pass_ends.empty() ? s.collapses.empty() : s.pass_ends.back() == s.collapses.size());
  std::vector<int64_t> owner(m.positions.size(), -1);
  for (size_t pass = 0; pass < s.pass_ends.size(); ++pass) {
    const size_t end = std::min<size_t>(s.pass_ends[pass], s.collapses.size());
    EXPECT_LT(begin, end) << "empty pass " << pass;
    // Triangles per vertex at the pass's start.
    std::vector<std::vector<uint32_t>> faces(m.positions.size());
    for (size_t f = 0; f < m.triangles.size(); ++f)
      if (alive[f])
        for (uint32_t v : m.triangles[f])
          if (faces[v].empty() || faces[v].back() != f) faces[v].push_back(uint32_t(f));
    // Closed one-rings: every vertex of a triangle of kept or removed belongs to one collapse only.
    for (size_t i = begin; i < end; ++i) {
      const EdgeCollapse& c = s.collapses[i];
      bool is_edge = false;
      for (uint32_t f : faces[c.kept])
        for (uint32_t w : m.triangles[f]) is_edge |= w == c.removed;
      EXPECT_TRUE(is_edge) << "collapse " << i << " is not an edge";
      for (uint32_t v : {c.kept, c.removed})
        for (uint32_t f : faces[v])
          for (uint32_t w : m.triangles[f]) {
            if (owner[w] >= int64_t(begin) && owner[w] != int64_t(i))
              ADD_FAILURE() << "pass " << pass << ": collapses " << owner[w] << " and " << i << " share vertex " << w;
            owner[w] = int64_t(i);
          }
    }
    // Apply, as the header defines a collapse (the rings are disjoint, so the start's adjacency is current).
    for (size_t i = begin; i < end; ++i) {
      const EdgeCollapse& c = s.collapses[i];
      for (uint32_t f : faces[c.removed]) {
        auto& t = m.triangles[f];
        const bool hk = t[0] == c.kept || t[1] == c.kept || t[2] == c.kept;
        if (hk) {
          alive[f] = 0;
        } else {
          for (auto& v : t)
            if (v == c.removed) v = c.kept;
        }
      }
      // The placement index names the position (the paper's 0/1/2).
      EXPECT_LE(c.placement, 2) << "collapse " << i;
      if (c.placement == 0) {
        EXPECT_EQ(c.position, m.positions[c.kept]) << "collapse " << i;
      } else if (c.placement == 1) {
        EXPECT_EQ(c.position, m.positions[c.removed]) << "collapse " << i;
      } else {
        EXPECT_NE(c.position, m.positions[c.kept]) << "collapse " << i;
        EXPECT_NE(c.position, m.positions[c.removed]) << "collapse " << i;
      }
      m.positions[c.kept] = c.position;
    }
    begin = end;
  }
  QuantizedMesh out;
  out.positions = m.positions;
  for (size_t f = 0; f < m.triangles.size(); ++f)
    if (alive[f]) out.triangles.push_back(m.triangles[f]);
  return out;
}

// The vertices `mesh` uses, by flag.
inline std::vector<uint8_t> usedVertices(const QuantizedMesh& m) {
  std::vector<uint8_t> used(m.positions.size(), 0);
  for (const auto& t : m.triangles)
    for (uint32_t v : t) used[v] = 1;
  return used;
}

// Triangle counts per undirected edge.
inline std::map<std::pair<uint32_t, uint32_t>, int> edgeCounts(const QuantizedMesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> e;
  for (const auto& t : m.triangles)
    for (int i = 0; i < 3; ++i) {
      const uint32_t a = t[i], b = t[(i + 1) % 3];
      if (a != b) e[{std::min(a, b), std::max(a, b)}]++;
    }
  return e;
}

// The simplifier's guarantees on its output: the replay gives exactly `s.mesh`, no new degenerate or duplicate
// triangle, no new non-manifold edge when the input had none, locked vertices in place, stats consistent.
inline void expectValidSimplification(const QuantizedMesh& input, std::span<const uint8_t> locked,
                                      const Simplification& s) {
  const QuantizedMesh replayed = replayCollapses(input, s);
  EXPECT_EQ(replayed.triangles, s.mesh.triangles) << "replaying the collapses gives the result";
  const auto used = usedVertices(s.mesh);
  for (size_t v = 0; v < used.size(); ++v)
    if (used[v]) {
      EXPECT_EQ(replayed.positions[v], s.mesh.positions[v]) << "vertex " << v;
    }
  ASSERT_EQ(s.pass_errors.size(), s.pass_ends.size());
  ASSERT_EQ(s.pass_faces.size(), s.pass_ends.size());
  if (!s.pass_faces.empty()) {
    EXPECT_EQ(s.pass_faces.back(), s.mesh.triangles.size());
  }
  float max_error = 0;
  for (const auto& c : s.collapses) max_error = std::max(max_error, c.error);
  if (!s.pass_errors.empty()) {
    EXPECT_EQ(s.pass_errors.back(), max_error);
  }
  // Degenerate and duplicate triangles: none that the input did not have.
  auto degenerate = [](const QuantizedMesh& m) {
    size_t n = 0;
    for (const auto& t : m.triangles) {
      const auto &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
      n += (a == b || b == c || a == c) ? 1 : 0;
    }
    return n;
  };
  EXPECT_LE(degenerate(s.mesh), degenerate(input));
  auto duplicates = [](const QuantizedMesh& m) {
    std::vector<std::array<uint32_t, 3>> sorted;
    for (auto t : m.triangles) {
      std::sort(t.begin(), t.end());
      sorted.push_back(t);
    }
    std::sort(sorted.begin(), sorted.end());
    return sorted.size() - size_t(std::unique(sorted.begin(), sorted.end()) - sorted.begin());
  };
  EXPECT_LE(duplicates(s.mesh), duplicates(input)) << "no new duplicate triangle";
  // Edges with more than two triangles: none when the input has none.
  bool input_manifold = true;
  for (const auto& [e, n] : edgeCounts(input)) input_manifold &= n <= 2;
  if (input_manifold)
    for (const auto& [e, n] : edgeCounts(s.mesh)) {
      EXPECT_LE(n, 2) << "edge " << e.first << "-" << e.second;
    }
  for (size_t v = 0; v < locked.size(); ++v)
    if (locked[v]) {
      EXPECT_EQ(s.mesh.positions[v], input.positions[v]) << "locked vertex " << v << " moved";
      for (const auto& c : s.collapses) {
        EXPECT_NE(c.removed, v) << "locked vertex " << v << " removed";
      }
    }
}

}  // namespace scanpress::testing
