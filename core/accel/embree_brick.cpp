#include "core/accel/embree_brick.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

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

// A little beyond t (2^-18 relative, about 32 float ulps). Embree accepts a
// candidate when T <= |den| * tfar on rescaled values and reports t = T *
// rcp(|den|), so a triangle at exactly the ray's best t from another brick (a
// duplicate, a shared edge) can fail a tfar of exactly t (one ray in twenty
// in the tests). Tracing up to widen(t) lets Embree report it, and
// hit_is_better() then settles the tie by ids (or rejects a t beyond the
// best).
inline float widen(float t) {
  constexpr float kMargin = 0x1p-18f;
  return t + std::fabs(t) * kMargin;
}

inline void fill_ray(const Ray& ray, float tfar, RTCRay& out) {
  out.org_x = ray.origin.x;
  out.org_y = ray.origin.y;
  out.org_z = ray.origin.z;
  out.tnear = ray.tnear;
  out.dir_x = ray.direction.x;
  out.dir_y = ray.direction.y;
  out.dir_z = ray.direction.z;
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

// Rays go to Embree in chunks of kChunk (in the order given). A chunk whose
// rays share a direction octant, whose unit directions lie within
// kCoherentDirectionSpread of each other (per axis, about 6 degrees) and whose
// origins lie within kCoherentOriginSpread of the brick's size — camera,
// lidar or light-probe rays, sorted — is traced as one stream with
// RTC_INTERSECT_CONTEXT_FLAG_COHERENT (rtcIntersect1M / rtcOccluded1M), which
// Embree traverses as packets: measured 1.5-2x faster for 1024^2 camera rays
// on the bunny, but 3x slower than rtcIntersect1 for incoherent rays, hence
// the test. Any other chunk goes through rtcIntersect1 / rtcOccluded1 ray by
// ray. Both paths give bitwise identical t, u, v and the same triangle
// (checked by the tests, duplicates included), so the answer does not depend
// on which path a ray took, i.e. on the batch it came in.
constexpr std::size_t kChunk = 256;
constexpr std::size_t kCoherentMinRays = 16;
constexpr float kCoherentDirectionSpread = 0.1f;
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
  bool coherent(float brick_size) const {
    if (count_ < kCoherentMinRays || octant_or_ != octant_and_) return false;
    for (int a = 0; a < 3; ++a) {
      if (!(dir_hi_[a] - dir_lo_[a] <= kCoherentDirectionSpread)) return false;
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

Expected<std::unique_ptr<EmbreeBrickAccel>> EmbreeBrickAccel::build(BrickData&& brick,
                                                                    const EmbreeBrickConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t n = brick.triangles.size();
  const std::string what = "building brick " + std::to_string(brick.brick_id) + " (embree)";
  if (brick.ids.size() != n) {
    return invalid_argument(what + ": " + std::to_string(n) + " triangles but " +
                            std::to_string(brick.ids.size()) + " ids");
  }
  if (n > kMaxTriangles) {
    return out_of_range(what + ": " + std::to_string(n) + " triangles, at most " +
                        std::to_string(kMaxTriangles));
  }
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

  if (kept > 0) {
    EmbreeDevice::ExclusiveSection section(*device);
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
      rtcCommitGeometry(geometry);
      rtcAttachGeometryByID(scene, geometry, 0);
      rtcReleaseGeometry(geometry);
      // Isolated: while this thread waits inside the commit it must not pick
      // up an outer task (say, another brick's build) that would block on the
      // allocation mutex this thread holds.
      tbb::this_task_arena::isolate([&] { rtcCommitScene(scene); });
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
  EmbreeDevice::ExclusiveSection section(**device);
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

// No intersection filter: Embree's closest hit inside the brick is taken as
// is (a filter callback on every candidate cost about a third of the trace
// time). Whatever Embree reports replaces the ray's hit only when
// hit_is_better() says so, which settles ties with hits from other bricks
// (and rejects a t that Embree's rescaled tfar test let past by an ulp).
void EmbreeBrickAccel::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  if (scene_ == nullptr) return;
  RTCRayHit found[kChunk];
  uint32_t found_ray[kChunk];
  RTCIntersectContext incoherent;
  rtcInitIntersectContext(&incoherent);  // RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT
  for (std::size_t begin = 0; begin < ray_ids.size(); begin += kChunk) {
    const std::size_t end = std::min(ray_ids.size(), begin + kChunk);
    std::size_t count = 0;
    for (std::size_t j = begin; j < end; ++j) {
      const uint32_t i = ray_ids[j];
      const Ray& ray = rays[i];
      const float tfar = std::min(ray.tfar, widen(hits[i].t));
      if (!(tfar > ray.tnear)) continue;  // nothing in (tnear, tfar] can improve it
      RTCRayHit& rayhit = found[count];
      fill_ray(ray, tfar, rayhit.ray);
      rayhit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rayhit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      found_ray[count++] = i;
    }
    // One ray at a time (closest hit never goes as a coherent stream: without
    // the tie filter, Embree's packet traversal can pick another of two
    // triangles at bitwise equal t than single-ray traversal, which would make
    // the answer depend on the batch). A hit's record (a random access into megabytes) is
    // prefetched as soon as the ray is traced and read kLag rays later, so the
    // cache miss overlaps with the next rays' traversal instead of stalling
    // (measured: about 10% of the trace time on the bunny).
    constexpr std::size_t kLag = 8;
    for (std::size_t c = 0; c < count; ++c) {
      rtcIntersect1(scene_, &incoherent, &found[c]);
      prefetch_hit(found[c]);
      if (c >= kLag) write_hits(found, found_ray, c - kLag, c - kLag + 1, hits);
    }
    write_hits(found, found_ray, count > kLag ? count - kLag : 0, count, hits);
  }
}

inline void EmbreeBrickAccel::prefetch_hit(const RTCRayHit& found) const {
  if (found.hit.geomID == RTC_INVALID_GEOMETRY_ID) return;
  const uint32_t prim = found.hit.primID;
  if (prim_is_triangle_) {
    __builtin_prefetch(&hit_records_[prim]);
    __builtin_prefetch(reinterpret_cast<const char*>(&hit_records_[prim]) + sizeof(HitRecord) - 1);
  } else {
    __builtin_prefetch(&indices_[3 * prim]);
  }
}

void EmbreeBrickAccel::write_hits(const RTCRayHit* found, const uint32_t* found_ray, std::size_t begin,
                                  std::size_t end, Hit* hits) const {
  for (std::size_t c = begin; c < end; ++c) {
    if (found[c].hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
    const uint32_t k = triangle_of(found[c].hit.primID);
    const HitRecord& record = hit_records_[k];
    const float t = found[c].ray.tfar;
    Hit& best = hits[found_ray[c]];
    if (!hit_is_better(t, record.geometry_id, record.primitive_id, best)) continue;
    best.t = t;
    best.geometry_id = record.geometry_id;
    best.primitive_id = record.primitive_id;
    best.u = found[c].hit.u;
    best.v = found[c].hit.v;
    best.normal = record.normal;
  }
}

void EmbreeBrickAccel::occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const {
  if (scene_ == nullptr) return;
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
    ChunkCoherence coherence;
    for (std::size_t j = begin; j < end; ++j) {
      const uint32_t i = ray_ids[j];
      const Ray& ray = rays[i];
      if (occluded[i] != 0 || !(ray.tfar > ray.tnear)) continue;
      fill_ray(ray, ray.tfar, found[count]);
      found_ray[count++] = i;
      coherence.add(ray);
    }
    if (coherence.coherent(max_extent_)) {
      rtcOccluded1M(scene_, &coherent, found, static_cast<unsigned>(count), sizeof(RTCRay));
      coherent_rays_.fetch_add(count, std::memory_order_relaxed);
    } else {
      for (std::size_t c = 0; c < count; ++c) rtcOccluded1(scene_, &incoherent, &found[c]);
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

}  // namespace outcore
