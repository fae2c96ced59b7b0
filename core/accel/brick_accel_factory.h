// Creates brick structures by name ("embree", "bvh", "kdtree", "bsp", "grid", "hgrid",
// "octree", "quadtree", "reference", "auto") with options
// given as key=value strings; unknown names and unknown or malformed options
// are errors, never ignored. The returned BrickBuilder turns a loaded brick into
// a BrickAccel.
//
// Thread-safety: a BrickBuilder may be called from several threads at once.
#pragma once

#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/accel/brick_accel.h"
#include "core/accel/brick_serializer.h"
#include "core/accel/resident_brick_set.h"
#include "core/geometry/hit_rounding.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"

namespace outcore {

// What the engine knows of a brick's use when it asks the cache for it
// (BrickCache::acquire): for builders that choose a structure per brick.
struct BuildDemand {
  // Rays the caller traces in the brick with this acquisition (0: unknown).
  uint64_t rays_now = 0;
  // Rays the brick is expected to serve while built: those it has served
  // since the cache was made, this acquisition's included (past use is the
  // guess at future use; 0: unknown).
  uint64_t rays_expected = 0;
};

class BrickBuilder {
 public:
  virtual ~BrickBuilder() = default;
  // Consumes the brick's data (the accel may keep its buffers).
  virtual Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const = 0;
  // build() for a brick with this demand; a builder that chooses a structure
  // per brick (auto) uses it, the others ignore it.
  virtual Expected<std::unique_ptr<BrickAccel>> build_for(BrickData&& brick,
                                                          const BuildDemand& /*demand*/) const {
    return build(std::move(brick));
  }
  // Whether `accel` (made by this builder) should be built again for
  // `demand`, a better structure paying for its build (auto's lazy
  // refinement). Called under the cache's lock: cheap, no I/O.
  virtual bool worth_rebuilding(const BrickAccel& /*accel*/, const BuildDemand& /*demand*/) const {
    return false;
  }
  // Whether build_for() and worth_rebuilding() use the demand: the engine
  // then counts, per brick, the rays of the batch that have it ahead.
  virtual bool uses_demand() const { return false; }
  // The structure (a brick_accel_names() name) `accel`, made by this
  // builder, is: name() unless the builder chooses per brick.
  virtual std::string_view structure_of(const BrickAccel& /*accel*/) const { return name(); }
  // An upper bound on memory_bytes() of the accel build() would return for
  // a brick of this many triangles, including the transient peak during the
  // build; the cache reserves it before building so it never overruns its budget.
  virtual uint64_t reserve_bytes(uint32_t triangle_count) const = 0;
  virtual const std::string& name() const = 0;
  // How to save and reload this builder's accels (the subtree tier), or
  // nullptr when the structure cannot be serialised (embree, reference).
  virtual const BrickSerializer* serializer() const { return nullptr; }
  // How far (relative to |ray origin| + |brick coordinates|) the exact ray
  // may pass from a triangle this structure's float test accepts: the brick
  // proxies' rounding bound (core/proxy/brick_proxy.h). Moeller-Trumbore's
  // unless the structure's test is watertight.
  virtual double hit_rounding_scale() const { return kMollerTrumboreHitRounding; }
  // The most bricks make_resident_set() serves well (0: it offers no set);
  // asked before the engine pins every brick for one.
  virtual uint32_t resident_set_max_bricks() const { return 0; }
  // One structure over `bricks` (each built by this builder and pinned while
  // the set lives; core/accel/resident_brick_set.h), or nullptr when the
  // structure has no such fast path.
  virtual Expected<std::unique_ptr<ResidentBrickSet>> make_resident_set(
      std::span<const BrickAccel* const> /*bricks*/) const {
    return std::unique_ptr<ResidentBrickSet>();
  }
};

using BrickAccelOptions = std::map<std::string, std::string>;

// The structure trace and serve use when none is named: the watertight bvh,
// exact at shared edges and vertices and, since issue 23, as fast as the
// alternatives (docs/BENCHMARKS.md, README "Which configuration").
inline constexpr const char* kDefaultBrickAccel = "bvh";

// Names: "embree" (options: robust=0|1, quality=low|medium|high); "bvh"
// (options: triangle_test=mt|watertight|double, default watertight; bins,
// max_leaf_size, traversal_cost, intersection_cost: BinnedSahBuilder::Config);
// "kdtree" (options: triangle_test as bvh; traversal_cost, intersection_cost,
// empty_bonus, max_depth: KdTreeBuilder::Config); "bsp" (options as kdtree,
// and directions=3|7|13: BspTreeBuilder::Config); "grid" (options:
// triangle_test as bvh; resolution=density|pbrt, cells_per_triangle,
// max_resolution: UniformGridBuilder::Config); "hgrid" (options:
// triangle_test as bvh; top_cells_per_triangle, cells_per_triangle,
// max_cell_triangles, max_levels: HierarchicalGridBuilder::Config); "octree" (options:
// triangle_test as bvh; max_leaf_size, max_depth: OctreeBuilder::Config);
// "quadtree" (options as octree: QuadtreeBuilder::Config); "reference" (no
// options: float64 brute force per brick, reference_brick.h); "auto" (options:
// candidates=a,b,... among bvh, kdtree, bsp, grid, hgrid, octree, quadtree;
// triangle_test, given to each; profile=FILE: the cost profile; per brick the
// candidate of least predicted cost: core/accel/auto/auto_brick.h).
Expected<std::unique_ptr<BrickBuilder>> make_brick_builder(const std::string& name,
                                                           const BrickAccelOptions& options);
std::vector<std::string> brick_accel_names();
// At most this many names (the cache counts builds per structure in an array).
inline constexpr std::size_t kMaxBrickStructures = 12;
// `name`'s position in brick_accel_names(), or kMaxBrickStructures when unknown.
std::size_t brick_structure_index(std::string_view name);
// "key=value key=value" in key order, or "defaults" when empty (for logs).
std::string describe_accel_options(const BrickAccelOptions& options);

}  // namespace outcore
