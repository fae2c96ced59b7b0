#include "core/accel/bsp/bsp_brick_serializer.h"

#include <cstdio>

namespace outcore {
namespace {

std::string key_of(const BspBrickConfig& config) {
  char key[256];
  std::snprintf(
      key, sizeof(key),
      "bsp/%d triangle_test=%s traversal_cost=%a intersection_cost=%a empty_bonus=%a "
      "max_depth=%u directions=%u",
      BspBrickSerializer::kPayloadVersion, std::string(triangle_test_name(config.triangle_test)).c_str(),
      static_cast<double>(config.builder.traversal_cost),
      static_cast<double>(config.builder.intersection_cost), static_cast<double>(config.builder.empty_bonus),
      config.builder.max_depth, config.builder.directions);
  return key;
}

}  // namespace

BspBrickSerializer::BspBrickSerializer(const BspBrickConfig& config)
    : SplitTreeSerializer(config.triangle_test, key_of(config)) {}

}  // namespace outcore
