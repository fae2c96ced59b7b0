#include "core/accel/embree_brick_set.h"

#include <algorithm>
#include <string>

#include "core/accel/embree_device.h"

namespace outcore {
namespace {

// Per instance: Embree's Instance object and its slot in the top-level
// scene, which Embree allocates without reporting to the memory monitor.
constexpr uint64_t kUntrackedBytesPerInstance = 512;

}  // namespace

Expected<std::unique_ptr<EmbreeBrickSet>> EmbreeBrickSet::build(
    std::span<const EmbreeBrickAccel* const> bricks) {
  OUTCORE_ASSIGN_OR_RETURN(EmbreeDevice * device, EmbreeDevice::instance());
  std::unique_ptr<EmbreeBrickSet> set(new EmbreeBrickSet());
  set->bricks_.assign(bricks.begin(), bricks.end());
  const auto has_scene = [](const EmbreeBrickAccel* b) { return b->scene_ != nullptr; };
  const auto with_scene = static_cast<uint64_t>(std::count_if(bricks.begin(), bricks.end(), has_scene));
  if (with_scene == 0) return set;
  if (with_scene == 1) {
    // One brick to trace: its own scene, without a level of instancing.
    const EmbreeBrickAccel* only = *std::find_if(bricks.begin(), bricks.end(), has_scene);
    set->scene_ = only->scene_;
    set->owns_scene_ = false;
    set->max_extent_ = only->max_extent_;
    set->center_ = only->center_;
    return set;
  }
  const std::string what = "building the scene over " + std::to_string(bricks.size()) + " resident bricks";
  // Column-major 3x4: the identity, no translation.
  static constexpr float kIdentity[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
  EmbreeDevice::MeasuredSection section(*device, /*allow_parallel=*/false);
  RTCScene scene = rtcNewScene(device->handle());
  if (scene == nullptr) {
    const Status status = device->take_error(what);
    return status.ok() ? internal_error(what + ": Embree returned null") : status;
  }
  bool robust = false;
  uint64_t instances = 0;
  for (const EmbreeBrickAccel* brick : bricks) {
    if (brick->scene_ == nullptr) continue;
    robust = robust || brick->config_.robust;
    RTCGeometry instance = rtcNewGeometry(device->handle(), RTC_GEOMETRY_TYPE_INSTANCE);
    if (instance == nullptr) break;  // the device's error is taken below
    rtcSetGeometryInstancedScene(instance, brick->scene_);
    rtcSetGeometryTransform(instance, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, kIdentity);
    rtcCommitGeometry(instance);
    rtcAttachGeometry(scene, instance);
    rtcReleaseGeometry(instance);
    ++instances;
  }
  rtcSetSceneFlags(scene, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  section.commit(scene);
  Status status = device->take_error(what);
  // A brick left out would lose its hits: never a partial set.
  if (status.ok() && instances != with_scene)
    status = internal_error(what + ": Embree returned a null instance");
  if (!status.ok()) {
    rtcReleaseScene(scene);
    return status;
  }
  RTCBounds bounds;
  rtcGetSceneBounds(scene, &bounds);
  const Vec3f lo(bounds.lower_x, bounds.lower_y, bounds.lower_z),
      hi(bounds.upper_x, bounds.upper_y, bounds.upper_z);
  const Vec3f extent = hi - lo;
  set->scene_ = scene;
  set->max_extent_ = std::max({extent.x, extent.y, extent.z});
  set->center_ = (lo + hi) * 0.5f;
  set->memory_bytes_ = static_cast<uint64_t>(std::max<int64_t>(0, section.delta_bytes())) +
                       instances * kUntrackedBytesPerInstance + EmbreeBrickAccel::kUntrackedBytes;
  return set;
}

EmbreeBrickSet::~EmbreeBrickSet() {
  if (scene_ == nullptr || !owns_scene_) return;
  auto device = EmbreeDevice::instance();  // exists: it made scene_
  EmbreeDevice::MeasuredSection section(**device, /*allow_parallel=*/false);
  rtcReleaseScene(scene_);
}

EmbreeBrickAccel::TraceTarget EmbreeBrickSet::target() const {
  return EmbreeBrickAccel::TraceTarget{scene_, max_extent_, center_, &coherent_rays_};
}

void EmbreeBrickSet::intersect(std::span<const uint32_t> ray_ids, const Ray* rays, Hit* hits) const {
  if (scene_ == nullptr) return;
  EmbreeBrickAccel::intersect_in(target(), ray_ids, rays, hits);
}

void EmbreeBrickSet::occluded(std::span<const uint32_t> ray_ids, const Ray* rays, uint8_t* occluded) const {
  if (scene_ == nullptr) return;
  EmbreeBrickAccel::occluded_in(target(), ray_ids, rays, occluded);
}

Expected<std::unique_ptr<ResidentBrickSet>> EmbreeBrickBuilder::make_resident_set(
    std::span<const BrickAccel* const> bricks) const {
  // Every brick of this builder is an EmbreeBrickAccel.
  std::vector<const EmbreeBrickAccel*> accels(bricks.size());
  for (std::size_t b = 0; b < bricks.size(); ++b) accels[b] = static_cast<const EmbreeBrickAccel*>(bricks[b]);
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<EmbreeBrickSet> set, EmbreeBrickSet::build(accels));
  return std::unique_ptr<ResidentBrickSet>(std::move(set));
}

}  // namespace outcore
