#include "core/accel/kdtree/kd_tree_brick_serializer.h"

#include <cstdio>

namespace outcore {
namespace {

std::string key_of(const KdTreeBrickConfig& config) {
  char key[256];
  std::snprintf(key, sizeof(key),
                "kdtree/%d triangle_test=%s traversal_cost=%a intersection_cost=%a empty_bonus=%a "
                "max_depth=%u",
                KdTreeBrickSerializer::kPayloadVersion,
                std::string(triangle_test_name(config.triangle_test)).c_str(),
                static_cast<double>(config.builder.traversal_cost),
                static_cast<double>(config.builder.intersection_cost),
                static_cast<double>(config.builder.empty_bonus), config.builder.max_depth);
  return key;
}

}  // namespace

KdTreeBrickSerializer::KdTreeBrickSerializer(const KdTreeBrickConfig& config)
    : SplitTreeSerializer(config.triangle_test, key_of(config)) {}

}  // namespace outcore
