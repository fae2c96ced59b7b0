#include "core/accel/brick_accel_factory.h"

#include <string>

#include "core/accel/embree_brick.h"

namespace outcore {
namespace {

std::string joined(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& name : names) out += (out.empty() ? "" : ", ") + name;
  return out;
}

Expected<std::unique_ptr<BrickBuilder>> make_embree_builder(const BrickAccelOptions& options) {
  EmbreeBrickConfig config;
  for (const auto& [key, value] : options) {
    if (key == "robust") {
      if (value == "0") {
        config.robust = false;
      } else if (value == "1") {
        config.robust = true;
      } else {
        return invalid_argument("brick accel embree: option robust must be 0 or 1, got '" + value + "'");
      }
    } else if (key == "quality") {
      if (value == "low") {
        config.quality = EmbreeQuality::kLow;
      } else if (value == "medium") {
        config.quality = EmbreeQuality::kMedium;
      } else if (value == "high") {
        config.quality = EmbreeQuality::kHigh;
      } else {
        return invalid_argument("brick accel embree: option quality must be low, medium or high, got '" + value + "'");
      }
    } else {
      return invalid_argument("brick accel embree: unknown option '" + key + "' (known: robust, quality)");
    }
  }
  return std::unique_ptr<BrickBuilder>(new EmbreeBrickBuilder(config));
}

}  // namespace

std::vector<std::string> brick_accel_names() { return {"embree"}; }

Expected<std::unique_ptr<BrickBuilder>> make_brick_builder(const std::string& name, const BrickAccelOptions& options) {
  if (name == "embree") return make_embree_builder(options);
  return not_found("unknown brick accel '" + name + "' (known: " + joined(brick_accel_names()) + ")");
}

}  // namespace outcore
