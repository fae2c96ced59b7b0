#include "tests/support/packed_scene.h"

#include <gtest/gtest.h>

#include "core/store/scene_packer.h"
#include "core/store/scene_store.h"

namespace outcore::testing {

std::unique_ptr<QueryEngine> open_test_engine(const PackedScene& scene, const std::string& brick_accel,
                                              uint64_t cache_bytes) {
  EngineOptions options;
  options.cache_bytes = cache_bytes;
  options.brick_accel = brick_accel;
  auto engine = QueryEngine::open(scene.path, options);
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  return engine.ok() ? std::move(engine).value() : nullptr;
}

std::unique_ptr<PackedScene> pack_test_scene(const std::vector<std::string>& inputs,
                                             uint32_t brick_triangles) {
  auto scene = std::make_unique<PackedScene>();
  scene->path = scene->dir.file("scene");
  PackOptions options;
  options.inputs = inputs;
  options.output = scene->path;
  options.brick_triangles = brick_triangles;
  options.sync = false;
  const auto summary = pack_scene(options);
  EXPECT_TRUE(summary.ok()) << summary.status().to_string();
  auto store = SceneStore::open(scene->path);
  EXPECT_TRUE(store.ok()) << store.status().to_string();
  if (!store.ok()) return scene;
  BrickData brick;
  for (uint32_t b = 0; b < (*store)->brick_count(); ++b) {
    EXPECT_TRUE((*store)->load_brick(b, brick).ok());
    scene->triangles.insert(scene->triangles.end(), brick.triangles.begin(), brick.triangles.end());
    scene->ids.insert(scene->ids.end(), brick.ids.begin(), brick.ids.end());
  }
  scene->bounds = (*store)->manifest().bounds;
  return scene;
}

}  // namespace outcore::testing
