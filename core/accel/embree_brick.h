// EmbreeBrickAccel: a brick's triangles in one Embree 3 scene (one triangle
// geometry over shared buffers), and EmbreeBrickBuilder, the BrickBuilder that
// makes them (registered as "embree" in brick_accel_factory.cpp).
//
// Buffers. The brick's triangle soup is Embree's vertex buffer as is (vertex
// 3k+j is vertex j of triangle k); Embree reads every vertex with a 16-byte
// load, so the soup needs 4 bytes of slack after its last vertex: a brick whose
// triangle vector has spare capacity is used in place, otherwise it is copied
// once into a vector of n + 1 triangles (the store can avoid the copy by
// reserving one extra triangle). The index buffer lists (3k, 3k+1, 3k+2) for
// every triangle that is not degenerate in float64 (Triangle::is_degenerate);
// degenerate ones are left out of the scene, which both saves BVH memory and
// keeps Embree's float arithmetic from reporting hits on triangles the float64
// reference can never hit. A 20-byte record per triangle holds what a hit
// reports besides t, u, v: the user's (geometry_id, primitive_id) and the unit
// normal, computed at build time (so a hit costs one cache miss, not three).
// Embree's primID maps to the triangle via the index buffer (or directly when
// no triangle was left out).
//
// Hits. A hit at t counts when tnear < t <= tfar (Embree's segment rule).
// intersect() traces each ray over (tnear, min(tfar, widen(hits[i].t))],
// widen(t) being t plus 2^-18 relative (about 32 float ulps), and decides in
// an Embree intersection filter (tie_filter) which candidates to accept: only
// those that beat the ray's best so far by hit_is_better()'s rule (nearer, or
// as near with a smaller (geometry_id, primitive_id)), the best starting as
// the hit the ray brought from other bricks. So ties are settled by the rule,
// never by the order bricks are visited in nor by Embree's traversal order —
// also between duplicate triangles inside one brick. The widening is needed
// because Embree tests T <= |den| * tfar on rescaled values and reports t = T
// * rcp(|den|): a duplicate at exactly the best t fails tfar = t for about
// one ray in twenty (measured), so without it the winner of a tie would
// depend on which brick came first (see TiesAcrossBricksFollowTheTieRule).
// The filter is what lets closest hit use coherent streams at all: without
// it Embree's packet traversal and its single-ray traversal can each pick
// another of two triangles at bitwise equal t, so the answer would depend
// on the batch (seen with duplicated triangles). It runs only on candidates
// that pass Embree's t test, reads ids only at an exact tie, and for a
// packet once per (packet, triangle): on the bunny's 1M incoherent rays the
// trace with it was within noise of the trace without it.
//
// Written per improved ray: t (Embree's float t), the user's ids, Embree's
// u, v (p = (1-u-v) v0 + u v1 + v v2) and the unit geometric normal computed
// in float64 from the stored vertices as normalize(cross(v1 - v0, v2 - v0)),
// rounded to float (at build time). That is Embree's sign convention — its
// Ng is cross(e2, e1) with e1 = v0 - v1, e2 = v2 - v0, i.e. cross(v1 - v0,
// v2 - v0), checked in NormalFollowsEmbreeNgSign — and therefore Open3D's
// (its primitive_normals are Embree's Ng normalised): the normal points to
// the side from which the vertices appear counter-clockwise, whichever side
// the ray comes from.
// Embree's u, v lose accuracy with the ray origin's distance over the
// triangle's size (about 1.5e-4 at a ratio of 300).
//
// Paths. Rays go to Embree in chunks of 256 in the order given, cut into
// runs of 64: a run of coherent rays (same direction octant, directions
// within ~6 degrees, origins close) as one rtcIntersect1M / rtcOccluded1M
// stream with the coherent flag (Embree traces it as packets; about 1.5-2x
// faster for camera rays), any other ray by rtcIntersect1 / rtcOccluded1.
// Both give bitwise equal results, ties included (tested with duplicated
// triangles here and in the engine), so a ray's answer does not depend on
// the batch it came in.
//
// Memory. memory_bytes() = the capacities of the triangle, hit-record and
// index buffers (68 B/tri) + the bytes Embree's memory monitor attributed to
// this scene (see EmbreeDevice) + kUntrackedBytes for the objects Embree
// allocates without reporting them (scene, geometry, accel headers) and this
// object. The build's
// peak (input brick, copies, buffers and Embree's peak during commit) is
// build_peak_bytes(); reserve_bytes() bounds both (formula and measurements in
// embree_brick.cpp).
//
// Thread-safety: build() may be called from many threads (the Embree part is
// serialised, see EmbreeDevice); a built accel is immutable and intersect() /
// occluded() may run concurrently on disjoint ray subsets. The destructor
// releases the scene under the device's allocation mutex.
#pragma once

#include <embree3/rtcore.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/store/brick_data.h"

namespace outcore {

enum class EmbreeQuality {
  kLow,     // Morton-code builder: fastest build, slowest traversal
  kMedium,  // binned SAH
  kHigh,    // binned SAH with spatial splits (not with robust): slowest build
};

struct EmbreeBrickConfig {
  // RTC_SCENE_FLAG_ROBUST: Embree avoids optimisations that lose accuracy
  // (watertight edge tests; no spatial splits, so quality high builds like
  // medium). Default off: 10-20% faster traversal, and the tests against
  // the float64 reference pass either way.
  bool robust = false;
  // RTC_BUILD_QUALITY_*. Default medium: see brick_accel_factory.cpp for the
  // measurement that chose it.
  EmbreeQuality quality = EmbreeQuality::kMedium;
};

class EmbreeBrickAccel final : public BrickAccel {
 public:
  // Largest brick: Embree's index buffer holds 3n uint32 vertex indices.
  static constexpr uint64_t kMaxTriangles = 0x55555554u;
  // Bytes Embree allocates per scene without reporting them to the monitor
  // (Scene, TriangleMesh, BVH headers, task-group state; 3.0-4.3 KiB per
  // scene measured with mallinfo2, EmbreeBrickMeasure.DISABLED_UntrackedBytes),
  // plus this object; counted in memory_bytes() with margin.
  static constexpr uint64_t kUntrackedBytes = 8 * 1024;

  // Consumes the brick. INVALID_ARGUMENT when ids and triangles differ in
  // count, OUT_OF_RANGE beyond kMaxTriangles, Embree's errors as Status.
  static Expected<std::unique_ptr<EmbreeBrickAccel>> build(BrickData&& brick,
                                                           const EmbreeBrickConfig& config);
  // Upper bound on memory_bytes() and build_peak_bytes() of a brick of n
  // triangles built with `config`.
  static uint64_t reserve_bytes(uint64_t triangle_count, const EmbreeBrickConfig& config);

  ~EmbreeBrickAccel() override;
  EmbreeBrickAccel(const EmbreeBrickAccel&) = delete;
  EmbreeBrickAccel& operator=(const EmbreeBrickAccel&) = delete;

  void intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const override;
  void occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const override;
  // Every hit and closest points scan the brick's triangles with the
  // watertight test (brick_queries.h): exact, where Embree's own test may
  // report a triangle twice (spatial splits) or lose an edge.
  void all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                std::vector<RayHitRecord>& out) const override;
  void closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                      ClosestPoint* best) const override;

  uint64_t memory_bytes() const override;
  double build_seconds() const override { return build_seconds_; }
  uint32_t triangle_count() const override { return static_cast<uint32_t>(hit_records_.size()); }

  // Beyond BrickAccel (statistics and tests):
  uint32_t brick_id() const { return brick_id_; }
  const EmbreeBrickConfig& config() const { return config_; }
  // Triangles in the Embree scene (the non-degenerate ones).
  uint32_t scene_triangle_count() const { return static_cast<uint32_t>(indices_.size() / 3); }
  // What Embree's memory monitor attributed to this scene after the commit.
  uint64_t embree_bytes() const { return embree_bytes_; }
  // Peak during build(): bytes of the consumed brick still alive, our buffers,
  // and Embree's peak during the commit, plus kUntrackedBytes.
  uint64_t build_peak_bytes() const { return build_peak_bytes_; }
  // Rays (closest and any hit) that went to Embree in coherent streams.
  uint64_t coherent_rays() const { return coherent_rays_.load(std::memory_order_relaxed); }

 private:
  EmbreeBrickAccel() = default;
  struct TieRecord;
  struct TieContext;
  friend class EmbreeBrickSet;
  // What the tracing loops run against: one brick's scene, or a scene
  // instancing many bricks (EmbreeBrickSet); its bounds for the coherence test.
  struct TraceTarget {
    RTCScene scene;
    float max_extent;
    Vec3f center;
    std::atomic<uint64_t>* coherent_rays;
  };
  static void intersect_in(const TraceTarget& target, std::span<const uint32_t> ray_ids, const Ray* rays,
                           Hit* hits);
  static void occluded_in(const TraceTarget& target, std::span<const uint32_t> ray_ids, const Ray* rays,
                          uint8_t* occluded);
  static void tie_filter(const RTCFilterFunctionNArguments* args);
  uint64_t buffer_bytes() const;
  void prefetch_hit(uint32_t prim) const;
  static void prefetch_hit(const TieRecord& record);
  static void write_hits(const RTCRayHit* found, const TieRecord* records, const uint32_t* found_ray,
                         std::size_t begin, std::size_t end, Hit* hits);
  // Largest per-axis spread of unit directions a coherent run may have, for
  // rays from about `origin` (see kCoherentAngularFraction).
  static float direction_spread_limit(const TraceTarget& target, const Vec3f& origin);
  // The brick triangle behind Embree's primID, and its user id as one key.
  uint32_t triangle_of(uint32_t prim) const { return prim_is_triangle_ ? prim : indices_[3 * prim] / 3; }
  uint64_t key_of(uint32_t prim) const;

  EmbreeBrickConfig config_;
  uint32_t brick_id_ = 0;
  RTCScene scene_ = nullptr;         // null for a brick without non-degenerate triangles
  std::vector<Triangle> triangles_;  // Embree's vertex buffer; capacity > size
  // Per triangle k: its unit normal (float64 computation rounded to float;
  // zero for a degenerate triangle, never hit) and the user's ids.
  using HitRecord = BvhHitRecord;
  std::vector<HitRecord> hit_records_;
  std::vector<uint32_t> indices_;  // Embree's index buffer; capacity > size
  bool prim_is_triangle_ = true;   // no degenerate left out: primID == k
  float max_extent_ = 0;           // largest side of the brick's bounds (coherence test)
  Vec3f center_;                   // centre of the brick's bounds (coherence test)
  uint64_t embree_bytes_ = 0;
  uint64_t build_peak_bytes_ = 0;
  double build_seconds_ = 0;
  mutable std::atomic<uint64_t> coherent_rays_{0};
};

class EmbreeBrickBuilder final : public BrickBuilder {
 public:
  explicit EmbreeBrickBuilder(const EmbreeBrickConfig& config) : config_(config) {}

  Expected<std::unique_ptr<BrickAccel>> build(BrickData&& brick) const override;
  uint64_t reserve_bytes(uint32_t triangle_count) const override {
    return EmbreeBrickAccel::reserve_bytes(triangle_count, config_);
  }
  const std::string& name() const override;
  // The resident bricks in one Embree scene (EmbreeBrickSet; defined in
  // embree_brick_set.cpp), made per batch.
  uint32_t resident_set_max_bricks() const override { return kResidentSetMaxBricks; }
  Expected<std::unique_ptr<ResidentBrickSet>> make_resident_set(
      std::span<const BrickAccel* const> bricks) const override;
  const EmbreeBrickConfig& config() const { return config_; }

 private:
  EmbreeBrickConfig config_;
};

}  // namespace outcore
