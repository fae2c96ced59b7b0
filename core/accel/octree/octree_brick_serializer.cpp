#include "core/accel/octree/octree_brick_serializer.h"

#include <cstdio>

namespace outcore {
namespace {

std::string key_of(const OctreeBrickConfig& config) {
  char key[160];
  std::snprintf(key, sizeof(key), "octree/%d triangle_test=%s max_leaf_size=%u max_depth=%u",
                OctreeBrickSerializer::kPayloadVersion,
                std::string(triangle_test_name(config.triangle_test)).c_str(), config.builder.max_leaf_size,
                config.builder.max_depth);
  return key;
}

}  // namespace

OctreeBrickSerializer::OctreeBrickSerializer(const OctreeBrickConfig& config)
    : SplitTreeSerializer(config.triangle_test, key_of(config)) {}

}  // namespace outcore
