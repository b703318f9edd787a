#include "engine/stages/stage.h"

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>

namespace scanpress {
namespace {

constexpr std::array<StageInfo, 2> kStages = {{
    {StageKind::kSmooth, "smooth", &smoothStage},
    {StageKind::kRemesh, "remesh", &remeshStage},
}};

// Unordered edges over positions, with how many triangles of the mesh use each.
struct PositionEdge {
  Vec3u a, b;  // a < b
  uint32_t uses;
};

std::vector<PositionEdge> lockedEdges(const TileView& t) {
  std::vector<std::pair<Vec3u, Vec3u>> edges;
  for (const auto& tri : t.mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t u = tri[k], v = tri[(k + 1) % 3];
      if (!t.locked[u] || !t.locked[v]) continue;
      Vec3u a = t.mesh.positions[u], b = t.mesh.positions[v];
      if (b < a) std::swap(a, b);
      edges.push_back({a, b});
    }
  std::sort(edges.begin(), edges.end());
  std::vector<PositionEdge> out;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    out.push_back({edges[i].first, edges[i].second, uint32_t(j - i)});
    i = j;
  }
  return out;
}

std::vector<Vec3u> lockedPositions(const TileView& t) {
  std::vector<Vec3u> out;
  for (size_t v = 0; v < t.mesh.positions.size(); ++v)
    if (t.locked[v]) out.push_back(t.mesh.positions[v]);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::string str(const Vec3u& p) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "(%u, %u, %u)", p[0], p[1], p[2]);
  return buf;
}

bool hasFlags(const TileView& t) { return t.locked.size() == t.mesh.positions.size(); }

}  // namespace

std::span<const StageInfo> allStages() { return kStages; }

Status validateStage(const StageSpec& spec) {
  switch (spec.kind) {
    case StageKind::kSmooth: {
      const SmoothOptions& o = spec.smooth;
      if (o.iterations < 0 || o.iterations > kMaxSmoothIterations)
        return makeError(ErrorCode::kInvalidArgument,
                         "iterations: must be in [0, " + std::to_string(kMaxSmoothIterations) + "]");
      if (!(o.lambda > 0 && o.lambda < 1)) return makeError(ErrorCode::kInvalidArgument, "lambda: must be in (0, 1)");
      if (!(o.mu > -1 && o.mu < -o.lambda))
        return makeError(ErrorCode::kInvalidArgument, "mu: must be in (-1, -lambda)");
      return Status::ok();
    }
    case StageKind::kRemesh: {
      const RemeshStageOptions& o = spec.remesh;
      if (!(o.grid > 0 && o.grid <= 1)) return makeError(ErrorCode::kInvalidArgument, "grid: must be in (0, 1]");
      if (!(o.tau > 0 && o.tau < 0.5773))
        return makeError(ErrorCode::kInvalidArgument, "tau: must be in (0, 0.5773) (below 1/sqrt(3))");
      return Status::ok();
    }
  }
  return makeError(ErrorCode::kInvalidArgument, "unknown stage");
}

const StageInfo* findStage(StageKind kind) {
  for (const auto& s : kStages)
    if (s.kind == kind) return &s;
  return nullptr;
}

const StageInfo* findStage(std::string_view name) {
  for (const auto& s : kStages)
    if (s.name == name) return &s;
  return nullptr;
}

std::string stageNames() {
  std::string out;
  for (const auto& s : kStages) out += (out.empty() ? "" : ", ") + std::string(s.name);
  return out;
}

Status checkBorderContract(const TileContext& ctx, const TileView& before, const TileView& after, bool thorough) {
  if (!hasFlags(after))
    return makeError(ErrorCode::kInternal, "border contract: " + std::to_string(after.locked.size()) +
                                               " lock flags for " + std::to_string(after.mesh.positions.size()) +
                                               " vertices");
  if (thorough) SP_RETURN_IF_ERROR(validateTile(ctx, after.mesh).withContext("border contract"));
  if (!hasFlags(before)) return Status::ok();  // nothing was locked
  const std::vector<Vec3u> kept = lockedPositions(after);
  for (const Vec3u& p : lockedPositions(before))
    if (!std::binary_search(kept.begin(), kept.end(), p))
      return makeError(ErrorCode::kInternal,
                       "border contract: locked vertex at " + str(p) + " was moved, removed or unlocked");
  const std::vector<PositionEdge> now = lockedEdges(after);
  for (const PositionEdge& e : lockedEdges(before)) {
    if (e.uses == 2) continue;  // interior to the tile
    const auto it = std::lower_bound(now.begin(), now.end(), e, [](const PositionEdge& x, const PositionEdge& y) {
      return std::pair(x.a, x.b) < std::pair(y.a, y.b);
    });
    if (it == now.end() || it->a != e.a || it->b != e.b)
      return makeError(ErrorCode::kInternal,
                       "border contract: border edge " + str(e.a) + " - " + str(e.b) + " was removed");
  }
  return Status::ok();
}

void undoDegenerateMoves(const QuantizedMesh& before, QuantizedMesh& after) {
  auto& q = after.positions;
  for (bool changed = true; changed;) {
    changed = false;
    for (const auto& t : after.triangles) {
      if (q[t[0]] != q[t[1]] && q[t[1]] != q[t[2]] && q[t[0]] != q[t[2]]) continue;
      for (uint32_t v : t)
        if (q[v] != before.positions[v]) {
          q[v] = before.positions[v];
          changed = true;
        }
    }
  }
}

Result<StagedTile> runStage(const TileContext& ctx, const TileView& tile, const StageSpec& spec, bool thorough) {
  const StageInfo* stage = findStage(spec.kind);
  if (!stage) return makeError(ErrorCode::kInvalidArgument, "unknown stage");
  SP_RETURN_IF_ERROR(validateStage(spec).withContext(std::string(stage->name)));
  SP_ASSIGN_OR_RETURN(StagedTile out, stage->run(ctx, tile, spec));
  SP_RETURN_IF_ERROR(checkBorderContract(ctx, tile, out.view(), thorough).withContext(std::string(stage->name)));
  return out;
}

}  // namespace scanpress
