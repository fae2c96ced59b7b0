#include "core/accel/bvh/bvh_tree.h"

#include <cereal/archives/binary.hpp>

#include <sstream>
#include <utility>

namespace outcore {

Status BvhTree::validate() const {
  if (records.size() != triangles.size()) {
    return invalid_argument("bvh: " + std::to_string(triangles.size()) + " triangles but " +
                            std::to_string(records.size()) + " hit records");
  }
  if (nodes.empty()) {
    if (!triangles.empty()) return invalid_argument("bvh: triangles but no nodes");
    return Status::Ok();
  }
  // Depth by a walk from the root; children strictly after their parent, so
  // there are no cycles and the walk ends.
  struct Item {
    uint32_t node, depth;
  };
  std::vector<Item> stack{{0, 1}};
  uint64_t covered = 0;
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    const BvhNode& node = nodes[item.node];
    if (item.depth > kMaxBvhDepth) {
      return invalid_argument("bvh: deeper than " + std::to_string(kMaxBvhDepth) + " at node " +
                              std::to_string(item.node));
    }
    if (node.is_leaf()) {
      if (uint64_t{node.index} + node.count > triangles.size()) {
        return invalid_argument("bvh: leaf " + std::to_string(item.node) + " reaches past the triangles");
      }
      covered += node.count;
      if (covered > triangles.size()) return invalid_argument("bvh: leaves overlap");
      continue;
    }
    if (node.index <= item.node || uint64_t{node.index} + 1 >= nodes.size()) {
      return invalid_argument("bvh: node " + std::to_string(item.node) + " has children out of range");
    }
    stack.push_back({node.index, item.depth + 1});
    stack.push_back({node.index + 1, item.depth + 1});
  }
  return Status::Ok();
}

std::string serialize_bvh(const BvhTree& tree) {
  std::ostringstream out;
  {
    cereal::BinaryOutputArchive archive(out);
    archive(tree);
  }
  return std::move(out).str();
}

Expected<BvhTree> deserialize_bvh(const std::string& bytes) {
  BvhTree tree;
  try {
    std::istringstream in(bytes);
    cereal::BinaryInputArchive archive(in);
    archive(tree);
  } catch (const std::exception& e) {
    return invalid_argument(std::string("bvh: cannot read serialised tree: ") + e.what());
  }
  OUTCORE_RETURN_IF_ERROR(tree.validate());
  return tree;
}

}  // namespace outcore
