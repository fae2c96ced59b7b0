// `--brick-accel auto`: each brick gets the candidate structure with the least
// predicted cost for the rays it is expected to serve,
//   cost(s) = build_s(brick) + rays_expected * trace_s(brick)
// (cost_profile.h; features: brick_features.h). The engine passes the demand
// with every acquisition (BuildDemand); a brick that keeps being used is
// rebuilt as a better structure once its rays pay for the build (lazy
// refinement: cheap first, upgraded later; worth_rebuilding()).
//
// Every candidate uses the same triangle test (watertight by default) and
// is an exact walk over it, so the choice never changes an answer, only the
// time. Candidates: bvh, kdtree, bsp, grid, hgrid, octree, quadtree (not
// embree, whose test differs, nor reference, float64).
//
// Thread-safety: the builder is immutable after construction; build_for()
// and worth_rebuilding() may run on many threads at once.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/accel/auto/brick_features.h"
#include "core/accel/auto/cost_profile.h"
#include "core/accel/brick_accel_factory.h"

namespace outcore {

// A brick built by the auto builder: the chosen candidate's accel, which
// structure it is, and the features the choice was made on (kept for
// refinement and saved with it).
class AutoBrickAccel final : public BrickAccel {
 public:
  AutoBrickAccel(std::unique_ptr<BrickAccel> inner, uint32_t candidate, const BrickFeatures& features)
      : inner_(std::move(inner)), candidate_(candidate), features_(features) {}

  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override {
    inner_->intersect(ray_ids, rays, hits);
  }
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override {
    inner_->occluded(ray_ids, rays, occluded);
  }
  void all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                std::vector<RayHitRecord>& out) const override {
    inner_->all_hits(ray_ids, rays, out);
  }
  void count_hits(std::span<const uint32_t> ray_ids, const Ray* rays, uint32_t* counts) const override {
    inner_->count_hits(ray_ids, rays, counts);
  }
  void closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                      ClosestPoint* best) const override {
    inner_->closest_points(point_ids, points, best);
  }
  uint64_t memory_bytes() const override { return inner_->memory_bytes() + sizeof(*this); }
  double build_seconds() const override { return inner_->build_seconds(); }
  uint32_t triangle_count() const override { return inner_->triangle_count(); }

  const BrickAccel& inner() const { return *inner_; }
  uint32_t candidate() const { return candidate_; }
  const BrickFeatures& features() const { return features_; }

 private:
  std::unique_ptr<BrickAccel> inner_;
  uint32_t candidate_;
  BrickFeatures features_;
};

// The predicted cost of each candidate for one brick and demand.
struct StructureChoice {
  uint32_t candidate = 0;
  std::vector<double> predicted_seconds;  // per candidate, build + rays * trace
};

class AutoBrickBuilder final : public BrickBuilder {
 public:
  struct Config {
    std::vector<std::string> candidates;  // empty: those of kDefaultAutoCandidates the profile has
    BrickAccelOptions candidate_options;  // given to each (triangle_test)
    std::string profile_path;             // empty: resolve_cost_profile("")
  };
  static Expected<std::unique_ptr<AutoBrickBuilder>> create(const Config& config);

  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override;
  Expected<std::unique_ptr<BrickAccel>> build_for(BrickData&& brick,
                                                  const BuildDemand& demand) const override;
  bool worth_rebuilding(const BrickAccel& accel, const BuildDemand& demand) const override;
  bool uses_demand() const override { return true; }
  std::string_view structure_of(const BrickAccel& accel) const override;
  uint64_t reserve_bytes(uint32_t triangle_count) const override;
  const std::string& name() const override { return name_; }
  const BrickSerializer* serializer() const override { return serializer_.get(); }
  double hit_rounding_scale() const override { return hit_rounding_scale_; }
  // A resident set exists when every brick chose the same candidate and that
  // candidate offers one (the bvh's): the set is that candidate's, over the
  // bricks' own structures. A mix gets none (nullptr; the engine then sweeps
  // the batch through the bricks instead).
  uint32_t resident_set_max_bricks() const override;
  Expected<std::unique_ptr<ResidentBrickSet>> make_resident_set(
      std::span<const BrickAccel* const> bricks) const override;

  // The candidate of least predicted cost for a brick with `features` that
  // is to serve `rays` rays (ties: the earlier candidate).
  StructureChoice choose(const BrickFeatures& features, uint64_t rays) const;
  const std::vector<std::string>& candidates() const { return candidate_names_; }
  // Candidates dropped because the profile never makes them the least cost
  // (never_chosen_candidates()).
  const std::vector<std::string>& dropped() const { return dropped_names_; }
  const CostProfile& profile() const { return profile_; }
  const BrickBuilder& candidate_builder(uint32_t candidate) const { return *builders_[candidate]; }

  // Rebuilding as the best candidate pays once the trace time the brick's
  // rays would have saved with it (rays_expected x the difference per ray)
  // exceeds this factor of its build (ski rental: within about twice the
  // best of building it first or never; the factor keeps choices from
  // flapping on noise).
  static constexpr double kRebuildMargin = 1.25;

 private:
  AutoBrickBuilder() = default;
  std::string name_ = "auto";
  std::vector<std::string> candidate_names_;
  std::vector<std::string> dropped_names_;
  std::vector<std::unique_ptr<BrickBuilder>> builders_;
  std::vector<StructureCost> costs_;  // per candidate, from the profile
  CostProfile profile_;
  double hit_rounding_scale_ = 0;
  std::unique_ptr<BrickSerializer> serializer_;  // null when a candidate has none
};

inline constexpr const char* kDefaultAutoCandidates[] = {"bvh",   "kdtree", "bsp",     "grid",
                                                         "hgrid", "octree", "quadtree"};

// The structures among `names` that `profile` says are never worth choosing:
// on no brick the profile was measured on (its samples; without any, probe
// bricks of 256 to 256 k triangles, flat to cubic, even to a teapot in a
// stadium, sparse to dense surface) and for no ray count (0, 1, 2, 4, ...
// 2^43) are they the least cost of `names`. The model is not trusted far
// from what was measured. Dropping them keeps the
// cache's reservation (the largest candidate's bound) from paying for
// structures that would never be built.
std::vector<std::string> never_chosen_candidates(const std::vector<std::string>& names,
                                                 const CostProfile& profile);

// The factory's maker: options candidates=a,b,..., triangle_test, profile.
Expected<std::unique_ptr<BrickBuilder>> make_auto_builder(const BrickAccelOptions& options);

}  // namespace outcore
