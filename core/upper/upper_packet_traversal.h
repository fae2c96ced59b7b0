// The first upper pass of eight coherent rays at once: the same windows of
// upcoming bricks as next_bricks_wide gives each ray from the start of its
// segment, found in one walk of the 4-wide upper hierarchy for all eight.
// Every box is tested against the eight rays in one AVX operation, and a node
// is fetched, its children's masks taken and the stack handled once for the
// packet instead of once per ray. Meant for rays that enter the same nodes
// (camera rays of neighbouring pixels): a node is entered when any lane
// enters it, so for rays that go separate ways it only adds tests.
//
// Bitwise the same keys as next_bricks_wide: each lane's entry into a box is
// computed by the same IEEE operations in the same order (no FMA; the target
// is AVX, not AVX2+FMA), and a lane takes a leaf only if its own test passes;
// which nodes a lane's subtree was entered through prunes nothing its leaves'
// own tests would keep (as in next_bricks_wide). Only the count of tested
// boxes differs, since the order of the walk and so the pruning of full
// windows differ.
//
// The AVX code is chosen at run time (the build targets x86-64-v2): call it
// on x86 only where cpu_has_avx() (core/util/cpu_features.h) is true;
// elsewhere a lane-by-lane form gives the same windows.
//
// Thread-safety: pure functions over an immutable WideUpper.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "core/upper/avx_slab.h"
#include "core/upper/upper_traversal.h"
#include "core/util/cpu_features.h"

namespace outcore {

// Eight rays' slab inputs, one row per axis (lanes beyond the packet unused).
// The walk inverts the directions itself, eight per division: IEEE division
// is correctly rounded, so each lane's inverse is bitwise SlabRay's.
struct SlabPacket {
  static constexpr uint32_t kLanes = 8;
  alignas(32) float origin[3][kLanes];
  alignas(32) float direction[3][kLanes];
  alignas(32) float tmin[kLanes];
  alignas(32) float tmax[kLanes];

  // Lane `lane` gets what SlabRay(ray) and [tmin, tmax] give next_bricks_wide.
  void set(uint32_t lane, const Ray& ray, float segment_min, float segment_max) {
    for (int axis = 0; axis < 3; ++axis) {
      origin[axis][lane] = ray.origin[axis];
      direction[axis][lane] = ray.direction[axis];
    }
    tmin[lane] = segment_min;
    tmax[lane] = segment_max;
  }
};

#if defined(__x86_64__) || defined(__i386__)
namespace detail {

// The slab test of one box against the eight rays: entries into `entry`,
// returns the mask of the lanes that pass with their own [tmin, limit].
// Per lane the operations of slab_test4 (min_exit is -inf: a first pass).
__attribute__((target("avx"))) inline uint32_t slab_test_packet(const SlabPacket& packet,
                                                                const float (&inverse_direction)[3][8],
                                                                const float lo[3], const float hi[3],
                                                                __m256 tmin, __m256 limit, float* entry) {
  __m256 near_all = tmin, far_all = limit;
  for (int axis = 0; axis < 3; ++axis) {
    const __m256 o = _mm256_load_ps(packet.origin[axis]);
    const __m256 inv = _mm256_load_ps(inverse_direction[axis]);
    const __m256 t0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(lo[axis]), o), inv);
    const __m256 t1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(hi[axis]), o), inv);
    fold_slab_axis_avx(t0, t1, near_all, far_all);
  }
  return finish_slab_avx(near_all, far_all, _mm256_set1_ps(-std::numeric_limits<float>::infinity()), entry);
}

}  // namespace detail

// For each lane k of `lanes` (bit k), fills windows[k] and found[k] as
// next_bricks_wide(wide, ray k, tmin[k], tmax[k], BrickKey{}, windows[k])
// would. Adds the boxes tested for each lane to nodes_visited.
template <std::size_t N>
__attribute__((target("avx"))) void first_bricks_wide_packet(const WideUpper& wide, const SlabPacket& packet,
                                                             uint32_t lanes,
                                                             std::array<BrickKey, N>* const* windows,
                                                             uint32_t* found, uint64_t& nodes_visited) {
  constexpr uint32_t kLanes = SlabPacket::kLanes;
  for (uint32_t lane = 0; lane < kLanes; ++lane) found[lane] = 0;
  if (wide.nodes.empty() || lanes == 0) return;
  const __m256 tmin = _mm256_load_ps(packet.tmin);
  alignas(32) float inverse_direction[3][kLanes];
  for (int axis = 0; axis < 3; ++axis) {
    _mm256_store_ps(inverse_direction[axis],
                    _mm256_div_ps(_mm256_set1_ps(1.0f), _mm256_load_ps(packet.direction[axis])));
  }
  // Per lane: tmax, or the largest key's entry once the window is full.
  alignas(32) float limit[kLanes];
  for (uint32_t lane = 0; lane < kLanes; ++lane) limit[lane] = packet.tmax[lane];
  const BrickKey after;
  struct Pending {
    uint32_t node;
    uint32_t lanes;
  };
  std::array<Pending, 3 * kMaxUpperDepth + 4> stack;
  uint32_t top = 0;
  stack[top++] = {0, lanes};
  while (top > 0) {
    const Pending pending = stack[--top];
    const WideUpper::Node& node = wide.nodes[pending.node];
    nodes_visited += uint64_t(node.count) * uint64_t(__builtin_popcount(pending.lanes));
    const __m256 lane_limit = _mm256_load_ps(limit);
    for (uint32_t k = 0; k < node.count; ++k) {
      const float lo[3] = {node.lo[0][k], node.lo[1][k], node.lo[2][k]};
      const float hi[3] = {node.hi[0][k], node.hi[1][k], node.hi[2][k]};
      alignas(32) float entry[kLanes];
      uint32_t mask = detail::slab_test_packet(packet, inverse_direction, lo, hi, tmin, lane_limit, entry) &
                      pending.lanes;
      if (mask == 0) continue;
      if (!(node.leaf_bits >> k & 1u)) {
        stack[top++] = {node.child[k], mask};
        continue;
      }
      while (mask != 0) {
        const uint32_t lane = static_cast<uint32_t>(__builtin_ctz(mask));
        mask &= mask - 1;
        const BrickKey key{entry[lane], node.child[k]};
        if (!(after < key)) continue;
        std::array<BrickKey, N>& window = *windows[lane];
        detail::insert_key(key, window, found[lane]);
        if (found[lane] == N) limit[lane] = std::min(packet.tmax[lane], window[N - 1].entry);
      }
    }
  }
}
#else
// Without x86: lane by lane (the same windows).
template <std::size_t N>
void first_bricks_wide_packet(const WideUpper& wide, const SlabPacket& packet, uint32_t lanes,
                              std::array<BrickKey, N>* const* windows, uint32_t* found,
                              uint64_t& nodes_visited) {
  for (uint32_t lane = 0; lane < SlabPacket::kLanes; ++lane) {
    found[lane] = 0;
    if (!(lanes >> lane & 1u)) continue;
    Ray lane_ray;
    lane_ray.origin = Vec3f(packet.origin[0][lane], packet.origin[1][lane], packet.origin[2][lane]);
    lane_ray.direction =
        Vec3f(packet.direction[0][lane], packet.direction[1][lane], packet.direction[2][lane]);
    const SlabRay ray(lane_ray);
    found[lane] = next_bricks_wide(wide, ray, packet.tmin[lane], packet.tmax[lane], BrickKey{},
                                   *windows[lane], nodes_visited);
  }
}
#endif

}  // namespace outcore
