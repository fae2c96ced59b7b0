#include "core/accel/quadtree/quadtree_brick_serializer.h"

#include <cstdio>

namespace outcore {
namespace {

std::string key_of(const QuadtreeBrickConfig& config) {
  char key[160];
  std::snprintf(key, sizeof(key), "quadtree/%d triangle_test=%s max_leaf_size=%u max_depth=%u",
                QuadtreeBrickSerializer::kPayloadVersion,
                std::string(triangle_test_name(config.triangle_test)).c_str(), config.builder.max_leaf_size,
                config.builder.max_depth);
  return key;
}

}  // namespace

QuadtreeBrickSerializer::QuadtreeBrickSerializer(const QuadtreeBrickConfig& config)
    : SplitTreeSerializer(config.triangle_test, key_of(config)) {}

}  // namespace outcore
