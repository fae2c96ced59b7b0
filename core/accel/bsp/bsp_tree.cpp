#include "core/accel/bsp/bsp_tree.h"

#include <cmath>
#include <string>
#include <utility>

namespace outcore {

Status BspTreeView::validate() const {
  if (records.size() != triangles.size()) {
    return invalid_argument("bsp tree: " + std::to_string(records.size()) + " hit records for " +
                            std::to_string(triangles.size()) + " triangles");
  }
  for (std::size_t k = 0; k < refs.size(); ++k) {
    if (refs[k] >= triangles.size()) {
      return invalid_argument("bsp tree: reference " + std::to_string(k) + " names triangle " +
                              std::to_string(refs[k]) + " of " + std::to_string(triangles.size()));
    }
  }
  if (nodes.empty()) return Status::Ok();
  // Depth-first from the root; every node is reached once (a node shared by
  // two parents would make the walk exponential); (node, depth) pending.
  std::vector<uint8_t> seen(nodes.size(), 0);
  std::vector<std::pair<uint32_t, uint32_t>> pending{{0u, 1u}};
  while (!pending.empty()) {
    const auto [index, depth] = pending.back();
    pending.pop_back();
    if (seen[index]++ != 0)
      return invalid_argument("bsp tree: node " + std::to_string(index) + " has two parents");
    if (depth > kMaxBspDepth) {
      return invalid_argument("bsp tree: deeper than " + std::to_string(kMaxBspDepth) + " at node " +
                              std::to_string(index));
    }
    const BspNode& node = nodes[index];
    if (node.is_leaf()) {
      if (uint64_t{node.first()} + node.count() > refs.size()) {
        return invalid_argument("bsp tree: leaf " + std::to_string(index) + " reaches past the " +
                                std::to_string(refs.size()) + " references");
      }
      continue;
    }
    if (node.direction() >= kBspDirectionCount) {
      return invalid_argument("bsp tree: node " + std::to_string(index) + " has direction " +
                              std::to_string(node.direction()) + " of " + std::to_string(kBspDirectionCount));
    }
    const uint32_t below = index + 1, above = node.above_child();
    if (below >= nodes.size() || above <= below || above >= nodes.size()) {
      return invalid_argument("bsp tree: node " + std::to_string(index) + " has children " +
                              std::to_string(below) + " and " + std::to_string(above) + " of " +
                              std::to_string(nodes.size()));
    }
    if (!std::isfinite(node.split()))
      return invalid_argument("bsp tree: node " + std::to_string(index) + " splits at " +
                              std::to_string(node.split()));
    pending.emplace_back(below, depth + 1);
    pending.emplace_back(above, depth + 1);
  }
  return Status::Ok();
}

}  // namespace outcore
