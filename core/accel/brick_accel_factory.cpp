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

// Defaults: robust=0, quality=medium. Measured on the bunny (69,451
// triangles, one brick), 1M incoherent rays, one thread, best of 8 alternated
// runs in each of three sessions (EmbreeBrickMeasure.DISABLED_DefaultChoice):
//
//   robust quality   build (1 thread)   intersect, M rays/s
//   0      low       0.010-0.011 s      2.2-2.6
//   0      medium    0.031-0.035 s      2.8-3.2   <- default
//   0      high      0.139-0.166 s      2.5-3.1
//   1      low       0.010-0.011 s      2.0-2.1
//   1      medium    0.032-0.033 s      2.3-2.6
//   1      high      0.031-0.036 s      2.4-2.8
//
// Medium traced fastest in every session (high, with spatial splits, was
// never faster on a mesh of evenly sized triangles) and builds 4-5x faster
// than high, whose spatial splits also cost up to 15% more peak memory and
// take 17x longer on 1M large overlapping triangles (6.6 s against 0.38 s,
// two threads). Robust costs
// 10-20% of trace speed for a watertightness the float64-reference tests did
// not need; it stays available for closed-mesh work.
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
        return invalid_argument("brick accel embree: option quality must be low, medium or high, got '" +
                                value + "'");
      }
    } else {
      return invalid_argument("brick accel embree: unknown option '" + key + "' (known: robust, quality)");
    }
  }
  return std::unique_ptr<BrickBuilder>(new EmbreeBrickBuilder(config));
}

}  // namespace

std::vector<std::string> brick_accel_names() {
  return {"embree"};
}

Expected<std::unique_ptr<BrickBuilder>> make_brick_builder(const std::string& name,
                                                           const BrickAccelOptions& options) {
  if (name == "embree") return make_embree_builder(options);
  return not_found("unknown brick accel '" + name + "' (known: " + joined(brick_accel_names()) + ")");
}

}  // namespace outcore
