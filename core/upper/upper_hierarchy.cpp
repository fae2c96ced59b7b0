#include "core/upper/upper_hierarchy.h"

#include <utility>

namespace outcore {

uint32_t UpperHierarchy::depth() const {
  if (nodes.empty()) return 0;
  uint32_t deepest = 0;
  std::vector<std::pair<uint32_t, uint32_t>> stack{{0u, 1u}};
  while (!stack.empty()) {
    const auto [index, level] = stack.back();
    stack.pop_back();
    const UpperNode& node = nodes[index];
    if (node.is_leaf) {
      deepest = std::max(deepest, level);
    } else {
      stack.push_back({node.child_or_brick, level + 1});
      stack.push_back({node.child_or_brick + 1, level + 1});
    }
  }
  return deepest;
}

}  // namespace outcore
