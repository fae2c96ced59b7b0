#include "core/accel/kdtree/split_tree_costs.h"

#include <algorithm>
#include <cmath>

#include "core/util/parse_number.h"

namespace outcore {
Status SplitTreeCosts::validate(std::string_view tree, uint32_t deepest) const {
  const std::string name(tree);
  if (!(traversal_cost > 0.0f) || !std::isfinite(traversal_cost)) {
    return invalid_argument(name + ": traversal_cost must be a positive number, got " +
                            std::to_string(traversal_cost));
  }
  if (!(intersection_cost > 0.0f) || !std::isfinite(intersection_cost)) {
    return invalid_argument(name + ": intersection_cost must be a positive number, got " +
                            std::to_string(intersection_cost));
  }
  if (!(empty_bonus >= 0.0f && empty_bonus < 1.0f)) {
    return invalid_argument(name + ": empty_bonus must be in [0, 1), got " + std::to_string(empty_bonus));
  }
  if (max_depth > deepest) {
    return invalid_argument(name + ": max_depth must be at most " + std::to_string(deepest) + ", got " +
                            std::to_string(max_depth));
  }
  return Status::Ok();
}

uint32_t SplitTreeCosts::depth_limit(uint64_t n, uint32_t deepest) const {
  if (max_depth != 0) return max_depth;
  const double automatic = 8.0 + 1.3 * std::log2(static_cast<double>(std::max<uint64_t>(n, 1)));
  return std::min<uint32_t>(deepest, static_cast<uint32_t>(std::lround(automatic)));
}

Expected<bool> SplitTreeCosts::parse_option(std::string_view structure, const std::string& key,
                                            const std::string& value) {
  const std::string what = "brick accel " + std::string(structure) + ": option " + key;
  if (key == "max_depth") {
    if (!parse_number(value, max_depth))
      return invalid_argument(what + " must be a whole number, got '" + value + "'");
    return true;
  }
  if (key != "traversal_cost" && key != "intersection_cost" && key != "empty_bonus") return false;
  float number = 0;
  if (!parse_number(value, number) || !std::isfinite(number)) {
    return invalid_argument(what + " must be a number, got '" + value + "'");
  }
  (key == "traversal_cost"      ? traversal_cost
   : key == "intersection_cost" ? intersection_cost
                                : empty_bonus) = number;
  return true;
}

}  // namespace outcore
