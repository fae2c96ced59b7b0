// PackedScene / pack_test_scene: a scene packed by the real packer into a
// temporary store, with every triangle and its ids read back (for brute-force
// references) and the scene's bounds. Shared by the engine tests (query
// engine, bvh engine, proxies, secondary rays).
//
// Thread-safety: call from the test's thread; failures are gtest failures.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/query/query_engine.h"
#include "core/store/brick_data.h"
#include "tests/support/test_paths.h"

namespace outcore::testing {

struct PackedScene {
  TempDir dir;
  std::string path;
  std::vector<Triangle> triangles;
  std::vector<TriangleId> ids;
  Aabb bounds;
};

// Packs `inputs` (paths or gen: specs) with at most brick_triangles per brick.
std::unique_ptr<PackedScene> pack_test_scene(const std::vector<std::string>& inputs,
                                             uint32_t brick_triangles);

// The engine over `scene` with `brick_accel` bricks and a cache of
// `cache_bytes` (a gtest failure, and null, when it does not open).
std::unique_ptr<QueryEngine> open_test_engine(const PackedScene& scene, const std::string& brick_accel,
                                              uint64_t cache_bytes = uint64_t{1} << 30);

}  // namespace outcore::testing
