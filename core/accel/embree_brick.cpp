#include "core/accel/embree_brick.h"

#include "core/accel/bvh/watertight_triangle_test.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "core/accel/brick_build_input.h"
#include "core/accel/embree_device.h"

namespace outcore {
namespace {

RTCBuildQuality rtc_quality(EmbreeQuality quality) {
  switch (quality) {
    case EmbreeQuality::kLow: return RTC_BUILD_QUALITY_LOW;
    case EmbreeQuality::kMedium: return RTC_BUILD_QUALITY_MEDIUM;
    case EmbreeQuality::kHigh: return RTC_BUILD_QUALITY_HIGH;
  }
  return RTC_BUILD_QUALITY_HIGH;
}

constexpr float kInfinity = std::numeric_limits<float>::infinity();
constexpr uint32_t kNoPrim = 0xffffffffu;

// A little beyond t (2^-18 relative, about 32 float ulps). Embree accepts a
// candidate when T <= |den| * tfar on rescaled values and reports t = T *
// rcp(|den|), so a triangle at exactly the best t (a duplicate of the best,
// here or in another brick) can fail a tfar of exactly t (one ray in twenty
// in the tests; a margin of 1 ulp already sufficed there); and a node that
// holds it could be culled by an ulp. Tracing up to widen(t) lets every such
// candidate reach the tie filter, which rejects whatever is beyond t.
inline float widen(float t) {
  constexpr float kMargin = 0x1p-18f;
  return t + std::fabs(t) * kMargin;
}

// How many rays ahead intersect() prefetches a ray and its hit while staging.
constexpr std::size_t kStagePrefetch = 8;

inline uint64_t id_key(uint32_t geometry_id, uint32_t primitive_id) {
  return (uint64_t{geometry_id} << 32) | primitive_id;
}

// Origins and directions go to Embree with negative zeros as +0 (x + 0 is x
// otherwise): the identity transform of an EmbreeBrickSet's instances turns
// -0 into +0, and a zero's sign can reach u and v, so every path feeds
// Embree the same values.
inline void fill_ray(const Ray& ray, float tfar, RTCRay& out) {
  out.org_x = ray.origin.x + 0.0f;
  out.org_y = ray.origin.y + 0.0f;
  out.org_z = ray.origin.z + 0.0f;
  out.tnear = ray.tnear;
  out.dir_x = ray.direction.x + 0.0f;
  out.dir_y = ray.direction.y + 0.0f;
  out.dir_z = ray.direction.z + 0.0f;
  out.time = 0.0f;
  out.tfar = tfar;
  out.mask = 0xffffffffu;
  out.id = 0;
  out.flags = 0;
}

Vec3f unit_normal(const Triangle& tri) {
  const Vec3d v0(tri.v0), v1(tri.v1), v2(tri.v2);
  const Vec3d n = cross(v1 - v0, v2 - v0);
  const double len = length(n);
  return Vec3f(n / len);  // len > 0: degenerate triangles are not in the scene
}

// Rays go to Embree in chunks of kChunk (in the order given), each cut into
// runs of kRun consecutive rays. A run whose
// rays share a direction octant, whose unit directions lie within
// kCoherentDirectionSpread of each other (per axis, about 6 degrees) and whose
// origins lie within kCoherentOriginSpread of the brick's size — camera,
// lidar or light-probe rays, sorted — is traced as one stream with
// RTC_INTERSECT_CONTEXT_FLAG_COHERENT (rtcIntersect1M / rtcOccluded1M), which
// Embree traverses as packets: faster for camera rays, far slower than
// rtcIntersect1 for incoherent ones, hence the test. Any other run goes through rtcIntersect1 / rtcOccluded1
// ray by ray. (Runs, not whole chunks: 256 consecutive pixels of a row-major 1000-pixel-wide image span 13
// degrees and fail the test; 64 span 3.) Both paths give bitwise identical t, u, v (checked by the tests),
// and ties are settled by the tie filter in both, so the answer does not depend on which path a ray took,
// i.e. on the batch it came in.
constexpr std::size_t kChunk = 256;
constexpr std::size_t kRun = 64;
constexpr std::size_t kCoherentMinRays = 16;
constexpr float kCoherentDirectionSpread = 0.1f;
// ... and within this fraction of the angle the brick subtends from the
// run's first origin: a run of camera rays that sweeps across a brick small
// on screen (a sphere of the city seen from afar) is no packet to Embree and
// runs slower as a stream than ray by ray (docs/BENCHMARKS_HISTORY.md,
// "Embree brick defaults").
constexpr float kCoherentAngularFraction = 1.0f;
constexpr float kCoherentOriginSpread = 0.1f;

class ChunkCoherence {
 public:
  void add(const Ray& ray) {
    const Vec3f& d = ray.direction;
    const uint32_t octant = (d.x < 0 ? 1u : 0u) | (d.y < 0 ? 2u : 0u) | (d.z < 0 ? 4u : 0u);
    octant_or_ |= octant;
    octant_and_ &= octant;
    ++count_;
    // Mixed octants already decide it: skip the spreads (incoherent chunks
    // are decided within a few rays, so they pay no square root per ray).
    if (octant_or_ != octant_and_) return;
    const float inv = 1.0f / std::sqrt(dot(d, d));
    for (int a = 0; a < 3; ++a) {
      dir_lo_[a] = std::min(dir_lo_[a], d[a] * inv);
      dir_hi_[a] = std::max(dir_hi_[a], d[a] * inv);
      origin_lo_[a] = std::min(origin_lo_[a], ray.origin[a]);
      origin_hi_[a] = std::max(origin_hi_[a], ray.origin[a]);
    }
  }
  bool coherent(float brick_size, float direction_spread) const {
    if (count_ < kCoherentMinRays || octant_or_ != octant_and_) return false;
    for (int a = 0; a < 3; ++a) {
      if (!(dir_hi_[a] - dir_lo_[a] <= direction_spread)) return false;
      if (!(origin_hi_[a] - origin_lo_[a] <= kCoherentOriginSpread * brick_size)) return false;
    }
    return true;
  }

 private:
  std::size_t count_ = 0;
  uint32_t octant_or_ = 0, octant_and_ = 7;
  float dir_lo_[3] = {2, 2, 2}, dir_hi_[3] = {-2, -2, -2};
  float origin_lo_[3] = {kInfinity, kInfinity, kInfinity},
        origin_hi_[3] = {-kInfinity, -kInfinity, -kInfinity};
};

}  // namespace

float EmbreeBrickAccel::direction_spread_limit(const TraceTarget& target, const Vec3f& origin) {
  const Vec3f offset = origin - target.center;
  const float distance = std::sqrt(dot(offset, offset));
  const float subtended = distance > 0 ? target.max_extent / distance : kCoherentDirectionSpread;
  return std::min(kCoherentDirectionSpread, kCoherentAngularFraction * subtended);
}

Expected<std::unique_ptr<EmbreeBrickAccel>> EmbreeBrickAccel::build(BrickData&& brick,
                                                                    const EmbreeBrickConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t n = brick.triangles.size();
  const std::string what = brick_build_context(brick, "embree");
  OUTCORE_RETURN_IF_ERROR(check_brick_build_input(brick, what, kMaxTriangles));
  OUTCORE_ASSIGN_OR_RETURN(EmbreeDevice * device, EmbreeDevice::instance());

  std::unique_ptr<EmbreeBrickAccel> accel(new EmbreeBrickAccel());
  accel->config_ = config;
  accel->brick_id_ = brick.brick_id;
  uint64_t peak = brick.memory_bytes();

  // Vertex buffer: the soup itself, with at least one spare triangle of slack
  // for Embree's 16-byte load of the last vertex.
  if (brick.triangles.capacity() > n) {
    accel->triangles_ = std::move(brick.triangles);
  } else {
    accel->triangles_.reserve(n + 1);
    accel->triangles_.assign(brick.triangles.begin(), brick.triangles.end());
    peak = std::max(peak, brick.memory_bytes() + accel->triangles_.capacity() * sizeof(Triangle));
  }
  brick.triangles = {};

  // What a hit reports besides t, u, v, per triangle in one 20-byte record:
  // one cache miss per hit instead of one for the id and two for the vertices.
  accel->hit_records_.resize(n);
  for (uint64_t k = 0; k < n; ++k) {
    const Triangle& tri = accel->triangles_[k];
    accel->hit_records_[k] = {tri.is_degenerate() ? Vec3f() : unit_normal(tri), brick.ids[k].geometry_id,
                              brick.ids[k].primitive_id};
  }
  peak = std::max(peak, brick.memory_bytes() + accel->buffer_bytes());
  brick.ids = {};

  // Index buffer over the non-degenerate triangles (those with a normal),
  // again with slack.
  const auto degenerate = [&](uint64_t k) { return accel->hit_records_[k].normal == Vec3f(); };
  uint64_t kept = 0;
  for (uint64_t k = 0; k < n; ++k) kept += degenerate(k) ? 0 : 1;
  accel->prim_is_triangle_ = kept == n;
  accel->indices_.reserve(3 * kept + 1);
  for (uint32_t k = 0; k < n; ++k) {
    if (!accel->prim_is_triangle_ && degenerate(k)) continue;
    accel->indices_.insert(accel->indices_.end(), {3 * k, 3 * k + 1, 3 * k + 2});
  }
  peak = std::max(peak, accel->buffer_bytes());
  Aabb bounds;
  for (const Triangle& tri : accel->triangles_) bounds.extend(tri.bounds());
  const Vec3f extent = bounds.extent();
  accel->max_extent_ = n > 0 ? std::max({extent.x, extent.y, extent.z}) : 0.0f;
  accel->center_ = n > 0 ? bounds.center() : Vec3f();

  if (kept > 0) {
    // Parallel when no other brick is committing in parallel (one large
    // brick builds on every core); otherwise on this thread, next to the
    // other builds.
    EmbreeDevice::MeasuredSection section(*device, /*allow_parallel=*/true);
    RTCScene scene = rtcNewScene(device->handle());
    RTCGeometry geometry =
        scene != nullptr ? rtcNewGeometry(device->handle(), RTC_GEOMETRY_TYPE_TRIANGLE) : nullptr;
    if (geometry != nullptr) {
      rtcSetSceneFlags(scene, config.robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
      rtcSetSceneBuildQuality(scene, rtc_quality(config.quality));
      rtcSetGeometryBuildQuality(geometry, rtc_quality(config.quality));
      rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                 accel->triangles_.data(), 0, sizeof(Vec3f), 3 * n);
      rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, accel->indices_.data(),
                                 0, 3 * sizeof(uint32_t), kept);
      rtcSetGeometryUserData(geometry, accel.get());
      rtcSetGeometryIntersectFilterFunction(geometry, &EmbreeBrickAccel::tie_filter);
      rtcCommitGeometry(geometry);
      rtcAttachGeometryByID(scene, geometry, 0);
      rtcReleaseGeometry(geometry);
      section.commit(scene);
    }
    Status status = device->take_error(what);
    if (status.ok() && (scene == nullptr || geometry == nullptr))
      status = internal_error(what + ": Embree returned null");
    if (!status.ok()) {
      if (scene != nullptr) rtcReleaseScene(scene);
      return status;
    }
    accel->scene_ = scene;
    accel->embree_bytes_ = static_cast<uint64_t>(std::max<int64_t>(0, section.delta_bytes()));
    peak = std::max(peak, accel->buffer_bytes() + static_cast<uint64_t>(section.peak_delta_bytes()));
  }
  accel->build_peak_bytes_ = peak + kUntrackedBytes;
  accel->build_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return accel;
}

EmbreeBrickAccel::~EmbreeBrickAccel() {
  if (scene_ == nullptr) return;
  auto device = EmbreeDevice::instance();  // exists: it made scene_
  EmbreeDevice::MeasuredSection section(**device, /*allow_parallel=*/false);
  rtcReleaseScene(scene_);
}

uint64_t EmbreeBrickAccel::buffer_bytes() const {
  return triangles_.capacity() * sizeof(Triangle) + hit_records_.capacity() * sizeof(HitRecord) +
         indices_.capacity() * sizeof(uint32_t);
}

uint64_t EmbreeBrickAccel::memory_bytes() const {
  return buffer_bytes() + embree_bytes_ + kUntrackedBytes;
}

// reserve_bytes(n) = 32 KiB + 248 n, or 32 KiB + 280 n with spatial splits
// (robust=0, quality=high), bounding both memory_bytes() and
// build_peak_bytes(). Measured with EmbreeBrickMeasure.DISABLED_MemoryTable
// (embree_brick_measure_test.cpp): bricks of 10, 100, 1e3, 1e4, 1e5 and 1e6
// triangles cut from the bunny (tiled beyond 69,451), an icosphere, random
// large overlapping triangles, small scattered triangles and a half-degenerate
// soup, with all six option combinations, each built from a vector without
// spare capacity (so the vertex copy is included). The worst build peak per
// triangle over all shapes (our buffers, 68 B/tri after the build, plus
// Embree's peak during commit, plus kUntrackedBytes), and the bound's ratio
// to it:
//
//   n                      10      100     1e3    1e4    1e5    1e6
//   low/medium/robust    1173    306.5   195.0  191.7  177.8  174.6  B/tri
//     bound / worst      3.01     1.88    1.44   1.31   1.40   1.42
//   spatial splits       1173    306.5   221.8  191.6  180.0  202.2  B/tri
//     bound / worst      3.03     1.98    1.41   1.48   1.56   1.38
//
// so at least 31% above the worst observed everywhere. After the build,
// memory_bytes() is 122-168 B/tri for n >= 1e4 (100-117 for the
// half-degenerate soup; low quality the most, its Morton builder leaving
// emptier leaves). Embree's bytes do not depend on the number of TBB threads:
// identical at medium and high quality for 1 to 32 threads, within one 2 MiB
// block at low.
uint64_t EmbreeBrickAccel::reserve_bytes(uint64_t triangle_count, const EmbreeBrickConfig& config) {
  constexpr uint64_t kBase = 32 * 1024;
  const bool spatial_splits = !config.robust && config.quality == EmbreeQuality::kHigh;
  return kBase + triangle_count * (spatial_splits ? 280 : 248);
}

// The best hit of one ray while it is traced through this brick: t, and who
// holds it — an Embree primID of this brick, or (prim == kNoPrim) the hit the
// ray brought from other bricks, by its user key.
struct EmbreeBrickAccel::TieRecord {
  float t;
  uint32_t prim;
  const EmbreeBrickAccel* holder;  // the brick of prim (null: kNoPrim)
  uint64_t key;
};

// Embree hands the filter this pointer as it was given to rtcIntersect*.
struct EmbreeBrickAccel::TieContext {
  RTCIntersectContext rtc;  // first member
  TieRecord* records;       // indexed by RTCRay::id
};

uint64_t EmbreeBrickAccel::key_of(uint32_t prim) const {
  const HitRecord& record = hit_records_[triangle_of(prim)];
  return id_key(record.geometry_id, record.primitive_id);
}

// Intersection filter: accepts a candidate only if it beats the ray's best by
// hit_is_better()'s rule (nearer, or as near with a smaller user id), so that
// ties are settled by the rule, not by traversal or brick order. On
// acceptance the segment is kept open to widen(t), so that candidates at
// exactly t elsewhere in the brick are still offered to this filter.
void EmbreeBrickAccel::tie_filter(const RTCFilterFunctionNArguments* args) {
  const auto* self = static_cast<const EmbreeBrickAccel*>(args->geometryUserPtr);
  TieRecord* records = reinterpret_cast<const TieContext*>(args->context)->records;
  const unsigned n = args->N;
  for (unsigned lane = 0; lane < n; ++lane) {
    if (args->valid[lane] != -1) continue;
    float& tfar = RTCRayN_tfar(args->ray, n, lane);  // the candidate's t
    const float t = tfar;
    const uint32_t prim = RTCHitN_primID(args->hit, n, lane);
    TieRecord& best = records[RTCRayN_id(args->ray, n, lane)];
    bool better = t < best.t;
    if (t == best.t)
      better = self->key_of(prim) < (best.prim != kNoPrim ? best.holder->key_of(best.prim) : best.key);
    if (!better) {
      args->valid[lane] = 0;
      continue;
    }
    best.t = t;
    best.prim = prim;
    best.holder = self;
    tfar = widen(t);
  }
}

void EmbreeBrickAccel::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  if (scene_ == nullptr) return;
  intersect_in(TraceTarget{scene_, max_extent_, center_, &coherent_rays_}, ray_ids, rays, hits);
}

void EmbreeBrickAccel::intersect_in(const TraceTarget& target, std::span<const uint32_t> ray_ids,
                                    const Ray* rays, Hit* hits) {
  TieRecord records[kChunk];
  RTCRayHit found[kChunk];
  uint32_t found_ray[kChunk];
  TieContext incoherent{{}, records};
  rtcInitIntersectContext(&incoherent.rtc);  // RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT
  TieContext coherent{{}, records};
  rtcInitIntersectContext(&coherent.rtc);
  coherent.rtc.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  for (std::size_t begin = 0; begin < ray_ids.size(); begin += kChunk) {
    const std::size_t end = std::min(ray_ids.size(), begin + kChunk);
    std::size_t count = 0;
    for (std::size_t j = begin; j < end; ++j) {
      // The rays of a queue are scattered over the batch: fetch a few ahead.
      if (j + kStagePrefetch < end) {
        __builtin_prefetch(&rays[ray_ids[j + kStagePrefetch]]);
        __builtin_prefetch(&hits[ray_ids[j + kStagePrefetch]]);
      }
      const uint32_t i = ray_ids[j];
      const Ray& ray = rays[i];
      const Hit& best = hits[i];
      const float tfar = std::min(ray.tfar, widen(best.t));
      if (!(tfar > ray.tnear)) continue;  // nothing in (tnear, tfar] can improve it
      records[count] = {best.t, kNoPrim, nullptr,
                        best.is_hit() ? id_key(best.geometry_id, best.primitive_id) : ~uint64_t{0}};
      RTCRayHit& rayhit = found[count];
      fill_ray(ray, tfar, rayhit.ray);
      rayhit.ray.id = static_cast<uint32_t>(count);  // the filter's index into records
      rayhit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rayhit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      found_ray[count++] = i;
    }
    // A hit's record (a random access into megabytes) is prefetched as soon
    // as the ray is traced and read kLag rays later, so the cache miss
    // overlaps with the next rays' traversal instead of stalling (measured:
    // about 10% of the trace time on the bunny).
    constexpr std::size_t kLag = 8;
    std::size_t written = 0;
    for (std::size_t run = 0; run < count; run += kRun) {
      const std::size_t run_end = std::min(count, run + kRun);
      ChunkCoherence coherence;
      for (std::size_t c = run; c < run_end; ++c) coherence.add(rays[found_ray[c]]);
      if (coherence.coherent(target.max_extent,
                             direction_spread_limit(target, rays[found_ray[run]].origin))) {
        rtcIntersect1M(target.scene, &coherent.rtc, found + run, static_cast<unsigned>(run_end - run),
                       sizeof(RTCRayHit));
        target.coherent_rays->fetch_add(run_end - run, std::memory_order_relaxed);
        for (std::size_t c = run; c < run_end; ++c) prefetch_hit(records[c]);
        continue;
      }
      for (std::size_t c = run; c < run_end; ++c) {
        rtcIntersect1(target.scene, &incoherent.rtc, &found[c]);
        prefetch_hit(records[c]);
        if (c >= written + kLag) {
          write_hits(found, records, found_ray, written, c + 1 - kLag, hits);
          written = c + 1 - kLag;
        }
      }
    }
    write_hits(found, records, found_ray, written, count, hits);
  }
}

inline void EmbreeBrickAccel::prefetch_hit(const TieRecord& record) {
  if (record.prim == kNoPrim) return;
  record.holder->prefetch_hit(record.prim);
}

inline void EmbreeBrickAccel::prefetch_hit(uint32_t prim) const {
  if (prim_is_triangle_) {
    __builtin_prefetch(&hit_records_[prim]);
    __builtin_prefetch(reinterpret_cast<const char*>(&hit_records_[prim]) + sizeof(HitRecord) - 1);
  } else {
    __builtin_prefetch(&indices_[3 * prim]);
  }
}

void EmbreeBrickAccel::write_hits(const RTCRayHit* found, const TieRecord* records, const uint32_t* found_ray,
                                  std::size_t begin, std::size_t end, Hit* hits) {
  for (std::size_t c = begin; c < end; ++c) {
    const TieRecord& record = records[c];
    if (record.prim == kNoPrim) continue;  // nothing here beats what the ray had
    assert(found[c].hit.primID == record.prim);
    const EmbreeBrickAccel& holder = *record.holder;
    const HitRecord& hit_record = holder.hit_records_[holder.triangle_of(record.prim)];
    Hit& best = hits[found_ray[c]];
    best.t = record.t;
    best.geometry_id = hit_record.geometry_id;
    best.primitive_id = hit_record.primitive_id;
    best.u = found[c].hit.u;  // Embree keeps the last accepted candidate's: the record's
    best.v = found[c].hit.v;
    best.normal = hit_record.normal;
  }
}

void EmbreeBrickAccel::occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const {
  if (scene_ == nullptr) return;
  occluded_in(TraceTarget{scene_, max_extent_, center_, &coherent_rays_}, ray_ids, rays, occluded);
}

void EmbreeBrickAccel::occluded_in(const TraceTarget& target, std::span<const uint32_t> ray_ids,
                                   const Ray* rays, uint8_t* occluded) {
  RTCRay found[kChunk];
  uint32_t found_ray[kChunk];
  RTCIntersectContext incoherent;
  rtcInitIntersectContext(&incoherent);
  RTCIntersectContext coherent;
  rtcInitIntersectContext(&coherent);
  coherent.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  for (std::size_t begin = 0; begin < ray_ids.size(); begin += kChunk) {
    const std::size_t end = std::min(ray_ids.size(), begin + kChunk);
    std::size_t count = 0;
    for (std::size_t j = begin; j < end; ++j) {
      const uint32_t i = ray_ids[j];
      const Ray& ray = rays[i];
      if (occluded[i] != 0 || !(ray.tfar > ray.tnear)) continue;
      fill_ray(ray, ray.tfar, found[count]);
      found_ray[count++] = i;
    }
    for (std::size_t run = 0; run < count; run += kRun) {
      const std::size_t run_end = std::min(count, run + kRun);
      ChunkCoherence coherence;
      for (std::size_t c = run; c < run_end; ++c) coherence.add(rays[found_ray[c]]);
      if (coherence.coherent(target.max_extent,
                             direction_spread_limit(target, rays[found_ray[run]].origin))) {
        rtcOccluded1M(target.scene, &coherent, found + run, static_cast<unsigned>(run_end - run),
                      sizeof(RTCRay));
        target.coherent_rays->fetch_add(run_end - run, std::memory_order_relaxed);
      } else {
        for (std::size_t c = run; c < run_end; ++c) rtcOccluded1(target.scene, &incoherent, &found[c]);
      }
    }
    for (std::size_t c = 0; c < count; ++c) {
      if (found[c].tfar == -kInfinity) occluded[found_ray[c]] = 1;  // Embree's mark for "blocked"
    }
  }
}

Expected<std::unique_ptr<BrickAccel>> EmbreeBrickBuilder::build(BrickData&& brick) const {
  OUTCORE_ASSIGN_OR_RETURN(auto accel, EmbreeBrickAccel::build(std::move(brick), config_));
  return std::unique_ptr<BrickAccel>(std::move(accel));
}

const std::string& EmbreeBrickBuilder::name() const {
  static const std::string kName = "embree";
  return kName;
}

void EmbreeBrickAccel::all_hits(std::span<const uint32_t> ray_ids, const Ray* rays,
                                std::vector<RayHitRecord>& out) const {
  all_hits_by_scan<WatertightTriangleTest>({triangles_.data(), hit_records_.size()}, hit_records_, ray_ids,
                                           rays, out);
}

void EmbreeBrickAccel::closest_points(std::span<const uint32_t> point_ids, const Vec3f* points,
                                      ClosestPoint* best) const {
  closest_points_by_scan({triangles_.data(), hit_records_.size()}, hit_records_, point_ids, points, best);
}

}  // namespace outcore
