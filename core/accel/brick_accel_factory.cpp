#include "core/accel/brick_accel_factory.h"

#include <cmath>
#include <iterator>
#include <string>

#include "core/accel/auto/auto_brick.h"
#include "core/accel/bsp/bsp_brick.h"
#include "core/accel/bvh/bvh_brick.h"
#include "core/accel/embree_brick.h"
#include "core/accel/grid/grid_brick.h"
#include "core/accel/hgrid/hgrid_brick.h"
#include "core/accel/kdtree/kd_tree_brick.h"
#include "core/accel/octree/octree_brick.h"
#include "core/accel/quadtree/quadtree_brick.h"
#include "core/accel/reference_brick.h"
#include "core/util/parse_number.h"

namespace outcore {
namespace {

std::string joined(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& name : names) out += (out.empty() ? "" : ", ") + name;
  return out;
}

// Defaults: robust=0, quality=medium: medium traced fastest and builds several
// times faster than high; robust costs trace speed for a watertightness the
// float64-reference tests did not need (figures: docs/BENCHMARKS_HISTORY.md,
// "Embree brick defaults").
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

// Default triangle_test=watertight: it is the configuration with zero leaks
// through shared edges and vertices (the stress suite checks it at every
// offset and scale) and agrees with the float64 reference except on true
// ties, at a modest cost over mt (docs/ACCURACY.md); mt leaks at vertices,
// double is the slower accuracy reference. The builder defaults are in
// BinnedSahBuilder::Config.
// The triangle_test option of the structures that take one.
Status parse_triangle_test(const std::string& structure, const std::string& value, TriangleTest& out) {
  const auto test = triangle_test_from_name(value);
  if (!test) {
    return invalid_argument("brick accel " + structure +
                            ": option triangle_test must be mt, watertight or double, got '" + value + "'");
  }
  out = *test;
  return Status::Ok();
}

Expected<std::unique_ptr<BrickBuilder>> make_bvh_builder(const BrickAccelOptions& options) {
  BvhBrickConfig config;
  BinnedSahBuilder::Config& b = config.builder;
  for (const auto& [key, value] : options) {
    if (key == "triangle_test") {
      OUTCORE_RETURN_IF_ERROR(parse_triangle_test("bvh", value, config.triangle_test));
    } else if (key == "bins" || key == "max_leaf_size") {
      uint32_t number = 0;
      if (!parse_number(value, number)) {
        return invalid_argument("brick accel bvh: option " + key + " must be a whole number, got '" + value +
                                "'");
      }
      (key == "bins" ? b.bin_count : b.max_leaf_size) = number;
    } else if (key == "traversal_cost" || key == "intersection_cost") {
      float number = 0;
      if (!parse_number(value, number) || !std::isfinite(number)) {
        return invalid_argument("brick accel bvh: option " + key + " must be a number, got '" + value + "'");
      }
      (key == "traversal_cost" ? b.traversal_cost : b.intersection_cost) = number;
    } else {
      return invalid_argument(
          "brick accel bvh: unknown option '" + key +
          "' (known: triangle_test, bins, max_leaf_size, traversal_cost, intersection_cost)");
    }
  }
  const Status valid = b.validate();
  if (!valid.ok()) return invalid_argument("brick accel " + valid.message());
  return std::unique_ptr<BrickBuilder>(new BvhBrickBuilder(config));
}

// The options of the structures over triangle references (kd-tree, BSP,
// grid, hgrid, octree, quadtree): triangle_test and their builder's own
// (Builder::Config::parse_option); false when `key` is none of them.
template <class Config>
Expected<bool> parse_split_tree_option(std::string_view structure, const std::string& key,
                                       const std::string& value, Config& config) {
  if (key == "triangle_test") {
    OUTCORE_RETURN_IF_ERROR(parse_triangle_test(std::string(structure), value, config.triangle_test));
    return true;
  }
  return config.builder.parse_option(structure, key, value);
}

// The structures whose options are triangle_test and their builder's own
// (Builder::Config::parse_option), listed in `known` for the error.
template <class BrickBuilderType>
Expected<std::unique_ptr<BrickBuilder>> make_indexed_builder(const char* name, const char* known,
                                                             const BrickAccelOptions& options) {
  typename BrickBuilderType::Config config;
  for (const auto& [key, value] : options) {
    OUTCORE_ASSIGN_OR_RETURN(const bool parsed, parse_split_tree_option(name, key, value, config));
    if (!parsed) {
      return invalid_argument(std::string("brick accel ") + name + ": unknown option '" + key +
                              "' (known: triangle_test, " + known + ")");
    }
  }
  const Status valid = config.builder.validate();
  if (!valid.ok()) return invalid_argument("brick accel " + valid.message());
  return std::unique_ptr<BrickBuilder>(new BrickBuilderType(config));
}

// Defaults: watertight (as the bvh) and SplitTreeCosts' constants.
Expected<std::unique_ptr<BrickBuilder>> make_kdtree_builder(const BrickAccelOptions& options) {
  return make_indexed_builder<KdTreeBrickBuilder>(
      "kdtree", "traversal_cost, intersection_cost, empty_bonus, max_depth", options);
}

// Defaults: watertight and BspTreeBuilder::Config's (the kd-tree's costs,
// all 13 directions).
Expected<std::unique_ptr<BrickBuilder>> make_bsp_builder(const BrickAccelOptions& options) {
  BspBrickConfig config;
  for (const auto& [key, value] : options) {
    OUTCORE_ASSIGN_OR_RETURN(const bool known, parse_split_tree_option("bsp", key, value, config));
    if (known) continue;
    if (key != "directions") {
      return invalid_argument("brick accel bsp: unknown option '" + key +
                              "' (known: triangle_test, traversal_cost, intersection_cost, empty_bonus, "
                              "max_depth, directions)");
    }
    if (!parse_number(value, config.builder.directions)) {
      return invalid_argument("brick accel bsp: option directions must be a whole number, got '" + value +
                              "'");
    }
  }
  const Status valid = config.builder.validate();
  if (!valid.ok()) return invalid_argument("brick accel " + valid.message());
  return std::unique_ptr<BrickBuilder>(new BspBrickBuilder(config));
}

// Defaults: watertight and UniformGridBuilder::Config's (the density rule,
// cells_per_triangle chosen by measurement: docs/BENCHMARKS.md).
Expected<std::unique_ptr<BrickBuilder>> make_grid_builder(const BrickAccelOptions& options) {
  return make_indexed_builder<GridBrickBuilder>("grid", "resolution, cells_per_triangle, max_resolution",
                                                options);
}

// Defaults: watertight and HierarchicalGridBuilder::Config's (a root cell
// per 16 triangles, the uniform grid's lambda in nested grids, nested in
// cells of more than 8 triangles, 3 levels).
Expected<std::unique_ptr<BrickBuilder>> make_hgrid_builder(const BrickAccelOptions& options) {
  return make_indexed_builder<HgridBrickBuilder>(
      "hgrid", "top_cells_per_triangle, cells_per_triangle, max_cell_triangles, max_levels", options);
}

// Defaults: watertight and OctreeBuilder::Config's (leaves of up to 8
// triangles, automatic depth).
Expected<std::unique_ptr<BrickBuilder>> make_octree_builder(const BrickAccelOptions& options) {
  return make_indexed_builder<OctreeBrickBuilder>("octree", "max_leaf_size, max_depth", options);
}

// Defaults: watertight and QuadtreeBuilder::Config's (as the octree's).
Expected<std::unique_ptr<BrickBuilder>> make_quadtree_builder(const BrickAccelOptions& options) {
  return make_indexed_builder<QuadtreeBrickBuilder>("quadtree", "max_leaf_size, max_depth", options);
}

Expected<std::unique_ptr<BrickBuilder>> make_reference_builder(const BrickAccelOptions& options) {
  if (!options.empty()) {
    return invalid_argument("brick accel reference: unknown option '" + options.begin()->first +
                            "' (it takes none)");
  }
  return std::unique_ptr<BrickBuilder>(new ReferenceBrickBuilder());
}

// Every brick structure, by the name users give it: a new structure is one
// line here (and its BrickAccel, BrickBuilder and optional BrickSerializer).
struct BrickStructureEntry {
  const char* name;
  Expected<std::unique_ptr<BrickBuilder>> (*make)(const BrickAccelOptions& options);
};
constexpr BrickStructureEntry kBrickStructures[] = {
    {"embree", make_embree_builder},       {"bvh", make_bvh_builder},
    {"kdtree", make_kdtree_builder},       {"bsp", make_bsp_builder},
    {"grid", make_grid_builder},           {"hgrid", make_hgrid_builder},
    {"octree", make_octree_builder},       {"quadtree", make_quadtree_builder},
    {"reference", make_reference_builder}, {"auto", make_auto_builder},
};
static_assert(std::size(kBrickStructures) <= kMaxBrickStructures);

}  // namespace

std::size_t brick_structure_index(std::string_view name) {
  for (std::size_t i = 0; i < std::size(kBrickStructures); ++i) {
    if (name == kBrickStructures[i].name) return i;
  }
  return kMaxBrickStructures;
}

std::vector<std::string> brick_accel_names() {
  std::vector<std::string> names;
  for (const BrickStructureEntry& entry : kBrickStructures) names.emplace_back(entry.name);
  return names;
}

Expected<std::unique_ptr<BrickBuilder>> make_brick_builder(const std::string& name,
                                                           const BrickAccelOptions& options) {
  for (const BrickStructureEntry& entry : kBrickStructures) {
    if (name == entry.name) return entry.make(options);
  }
  return not_found("unknown brick accel '" + name + "' (known: " + joined(brick_accel_names()) + ")");
}

std::string describe_accel_options(const BrickAccelOptions& options) {
  if (options.empty()) return "defaults";
  std::string text;
  for (const auto& [key, value] : options) text += (text.empty() ? "" : " ") + key + "=" + value;
  return text;
}

}  // namespace outcore
