// Traversal of the fixed upper hierarchy: finds, for one ray, the next bricks
// it reaches in front-to-back order, keyed by (entry distance, brick id). The
// engine keeps only a small window of upcoming bricks per ray and asks again
// when the window runs out, so memory per ray stays fixed however many bricks a
// ray crosses. The traversal knows nothing of caches or queues: it reports
// bricks, the scheduler decides what to do with them (as in madmann91/bvh,
// where traversal takes the leaf work as a callback).
//
// Robustness: slab tests are conservative (Ize 2013): the exit distance is
// scaled up and the entry distance down by 1 +/- 2^-18 (more than Ize's
// 2*gamma(3), see kSlabWiden), and a slab whose
// product is NaN (origin on a slab plane with a zero direction component)
// constrains nothing, so no box test loses a hit the triangle test would find.
//
// Thread-safety: pure functions over an immutable hierarchy.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core/ray/ray_types.h"
#include "core/upper/upper_hierarchy.h"

namespace outcore {

// Deepest upper hierarchy the fixed traversal stack supports; the manifest
// validation refuses deeper ones.
inline constexpr uint32_t kMaxUpperDepth = 128;

struct BrickKey {
  float entry = -std::numeric_limits<float>::infinity();
  uint32_t brick = 0;
  bool operator<(const BrickKey& o) const { return entry < o.entry || (entry == o.entry && brick < o.brick); }
  bool operator==(const BrickKey&) const = default;
};

// What the slab test needs of a ray, computed once per ray.
struct SlabRay {
  Vec3f origin;
  Vec3f inverse_direction;
  float pad = 0.0f;  // so that the SSE slab test loads inverse_direction as four floats

  explicit SlabRay(const Ray& ray)
      : origin(ray.origin),
        inverse_direction(1.0f / ray.direction.x, 1.0f / ray.direction.y, 1.0f / ray.direction.z) {}
};

namespace detail {
// Ize's 2*gamma(3) (gamma(n) = n*eps/(1-n*eps), eps = 2^-24, about 3.6e-7)
// covers the slab test's own rounding, but not the watertight triangle
// tests', which may accept a ray whose exact line passes a few ulps outside
// the triangle, and so outside its brick's box. 2^-18 (64 ulps) is the
// margin the bvh brick structure uses inside a brick for that reason
// (core/accel/bvh/bvh_traversal.h); the same here keeps seams between bricks
// no weaker than a brick's inside (the stress suite's seam cases: tiny
// bricks answer bitwise like one brick). The cost is a few more brick
// candidates for rays passing within 4e-6 relative of a brick's box.
inline constexpr float kSlabWiden = 0x1p-18f;

// std::fmin / std::fmax semantics (a NaN operand yields the other one) as
// selects the compiler inlines: without -ffast-math GCC calls libm's fminf /
// fmaxf through the PLT: a call per box test in the hottest loop.
inline float fmin_inline(float a, float b) {
  return b != b ? a : (a < b ? a : b);
}
inline float fmax_inline(float a, float b) {
  return b != b ? a : (a > b ? a : b);
}

// Conservative [entry, exit] of the ray against the box, clipped to [tmin, tmax];
// true when the segment touches the box and the exit is at least min_exit.
// The scalar form; slab_test is the same operations on SSE lanes.
inline bool slab_test_scalar(const SlabRay& ray, const Aabb& box, float tmin, float tmax, float min_exit,
                             float& entry) {
  float lo = tmin, hi = tmax;
  for (int axis = 0; axis < 3; ++axis) {
    const float t0 = (box.lo[axis] - ray.origin[axis]) * ray.inverse_direction[axis];
    const float t1 = (box.hi[axis] - ray.origin[axis]) * ray.inverse_direction[axis];
    const float near = fmin_inline(t0, t1);
    const float far = fmax_inline(t0, t1);
    // fmin/fmax return the other operand for one NaN; both are NaN only for
    // 0 * inf (origin on the slab plane, direction parallel to it), and then
    // the comparisons below are false: the slab constrains nothing.
    const float widened_near = near - std::fabs(near) * kSlabWiden;
    const float widened_far = far + std::fabs(far) * kSlabWiden;
    lo = widened_near > lo ? widened_near : lo;
    hi = widened_far < hi ? widened_far : hi;
  }
  entry = lo;
  return lo <= hi && hi >= min_exit;
}

static_assert(sizeof(Vec3f) == 12 && sizeof(Aabb) == 24 && sizeof(UpperNode) == 32);

// slab_test_scalar with the three axes on SSE lanes, bitwise the same result:
// the per-axis operations are the same IEEE operations, and entry and exit
// are folded in the same axis order (x, y, z) with the same selects, so even
// the sign of a zero entry agrees. Branch-free (the scalar form branches on
// NaN checks): the upper pass of a 732-brick scene visits ~21 nodes per ray.
// `box` is read as two 4-float loads (lo, hi and the next 4 bytes): it must
// be followed by 4 readable bytes, as in an UpperNode.
inline bool slab_test(const SlabRay& ray, const Aabb& box, float tmin, float tmax, float min_exit,
                      float& entry) {
#if defined(__SSE2__)
  static_assert(offsetof(SlabRay, pad) == offsetof(SlabRay, inverse_direction) + 12);
  // Lane 3 zeroed: no garbage (a brick id read as a denormal) in arithmetic.
  const __m128 xyz = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 o = _mm_and_ps(_mm_loadu_ps(&ray.origin.x), xyz);
  const __m128 inv = _mm_loadu_ps(&ray.inverse_direction.x);  // lane 3: pad = 0
  const __m128 t0 = _mm_mul_ps(_mm_sub_ps(_mm_and_ps(_mm_loadu_ps(&box.lo.x), xyz), o), inv);
  const __m128 t1 = _mm_mul_ps(_mm_sub_ps(_mm_and_ps(_mm_loadu_ps(&box.hi.x), xyz), o), inv);
  // fmin_inline / fmax_inline: minps / maxps give their second operand when
  // either is NaN, right for a NaN t0; a NaN t1 gives t0.
  const __m128 t1_nan = _mm_cmpunord_ps(t1, t1);
  const __m128 near = _mm_or_ps(_mm_and_ps(t1_nan, t0), _mm_andnot_ps(t1_nan, _mm_min_ps(t0, t1)));
  const __m128 far = _mm_or_ps(_mm_and_ps(t1_nan, t0), _mm_andnot_ps(t1_nan, _mm_max_ps(t0, t1)));
  const __m128 widen = _mm_set1_ps(kSlabWiden);
  const __m128 wn = _mm_sub_ps(near, _mm_mul_ps(_mm_and_ps(near, abs_mask), widen));
  const __m128 wf = _mm_add_ps(far, _mm_mul_ps(_mm_and_ps(far, abs_mask), widen));
  // lo = wn > lo ? wn : lo (maxss), hi = wf < hi ? wf : hi (minss), x then y then z.
  __m128 lo = _mm_max_ss(wn, _mm_set_ss(tmin));
  __m128 hi = _mm_min_ss(wf, _mm_set_ss(tmax));
  lo = _mm_max_ss(_mm_shuffle_ps(wn, wn, 1), lo);
  hi = _mm_min_ss(_mm_shuffle_ps(wf, wf, 1), hi);
  lo = _mm_max_ss(_mm_shuffle_ps(wn, wn, 2), lo);
  hi = _mm_min_ss(_mm_shuffle_ps(wf, wf, 2), hi);
  const float l = _mm_cvtss_f32(lo), h = _mm_cvtss_f32(hi);
  entry = l;
  return l <= h && h >= min_exit;
#else
  return slab_test_scalar(ray, box, tmin, tmax, min_exit, entry);
#endif
}
}  // namespace detail

// Fills `window` (sorted ascending) with the up to N smallest keys strictly
// greater than `after` among the bricks whose box the ray's segment
// [tmin, tmax] touches; returns how many were found. Counts visited nodes.
template <std::size_t N>
uint32_t next_bricks(const UpperHierarchy& upper, const SlabRay& ray, float tmin, float tmax,
                     const BrickKey& after, std::array<BrickKey, N>& window, uint64_t& nodes_visited) {
  uint32_t found = 0;
  if (upper.nodes.empty()) return 0;
  std::array<uint32_t, kMaxUpperDepth + 1> stack;
  uint32_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const uint32_t index = stack[--top];
    const UpperNode& node = upper.nodes[index];
    ++nodes_visited;
    // Once the window is full, only keys below its largest can enter.
    const float limit = found == N ? std::min(tmax, window[N - 1].entry) : tmax;
    float entry;
    // Boxes the ray has left before `after` hold no key greater than it.
    if (!detail::slab_test(ray, node.bounds, tmin, limit, after.entry, entry)) continue;
    if (!node.is_leaf) {
      stack[top++] = node.child_or_brick;
      stack[top++] = node.child_or_brick + 1;
      continue;
    }
    const BrickKey key{entry, node.child_or_brick};
    if (!(after < key)) continue;
    if (found == N && !(key < window[N - 1])) continue;
    // Insertion into the small sorted window.
    uint32_t pos = found < N ? found++ : N - 1;
    while (pos > 0 && key < window[pos - 1]) {
      window[pos] = window[pos - 1];
      --pos;
    }
    window[pos] = key;
  }
  return found;
}

// The leaves of a small upper hierarchy (at most kMaxLeaves bricks) as one
// flat structure-of-arrays, for next_bricks_flat. Built per batch: a scan of
// at most 2 kMaxLeaves - 1 nodes.
struct FlatLeaves {
  static constexpr uint32_t kMaxLeaves = 8;
  uint32_t count = 0;
  alignas(16) float lo[3][kMaxLeaves];
  alignas(16) float hi[3][kMaxLeaves];
  uint32_t brick[kMaxLeaves];
};

// Fills `flat` with the leaves of `upper`; false when it has more than
// kMaxLeaves leaves (or none).
inline bool make_flat_leaves(const UpperHierarchy& upper, FlatLeaves& flat) {
  flat.count = 0;
  if (upper.nodes.empty() || upper.nodes.size() > 2 * FlatLeaves::kMaxLeaves - 1) return false;
  for (const UpperNode& node : upper.nodes) {
    if (!node.is_leaf) continue;
    const uint32_t j = flat.count++;
    for (int axis = 0; axis < 3; ++axis) {
      flat.lo[axis][j] = node.bounds.lo[axis];
      flat.hi[axis][j] = node.bounds.hi[axis];
    }
    flat.brick[j] = node.child_or_brick;
  }
  // Unused lanes are computed but never reported.
  for (uint32_t j = flat.count; j < FlatLeaves::kMaxLeaves; ++j) {
    for (int axis = 0; axis < 3; ++axis) flat.lo[axis][j] = flat.hi[axis][j] = 0.0f;
    flat.brick[j] = kInvalidId;
  }
  return true;
}

namespace detail {
// The slab tests of four boxes at once, box k's bounds on axis a at lo[a *
// stride + k] and hi[a * stride + k] (16-byte aligned rows): entries into
// entry[0..3], returns the mask of the boxes passed (bit k for box k). Per box
// the same IEEE operations as slab_test_scalar, so bitwise the same entries.
inline uint32_t slab_test4(const SlabRay& ray, const float* lo_rows, const float* hi_rows, std::size_t stride,
                           float tmin, float tmax, float min_exit, float* entry) {
#if defined(__SSE2__)
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 widen = _mm_set1_ps(kSlabWiden);
  __m128 lo = _mm_set1_ps(tmin), hi = _mm_set1_ps(tmax);
  for (int axis = 0; axis < 3; ++axis) {
    const __m128 o = _mm_set1_ps(ray.origin[axis]);
    const __m128 inv = _mm_set1_ps(ray.inverse_direction[axis]);
    const __m128 t0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(lo_rows + axis * stride), o), inv);
    const __m128 t1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(hi_rows + axis * stride), o), inv);
    // fmin_inline / fmax_inline: minps / maxps return their second operand
    // when either is NaN, which is right for a NaN t0; a NaN t1 yields t0.
    const __m128 t1_nan = _mm_cmpunord_ps(t1, t1);
    const __m128 near = _mm_or_ps(_mm_and_ps(t1_nan, t0), _mm_andnot_ps(t1_nan, _mm_min_ps(t0, t1)));
    const __m128 far = _mm_or_ps(_mm_and_ps(t1_nan, t0), _mm_andnot_ps(t1_nan, _mm_max_ps(t0, t1)));
    const __m128 widened_near = _mm_sub_ps(near, _mm_mul_ps(_mm_and_ps(near, abs_mask), widen));
    const __m128 widened_far = _mm_add_ps(far, _mm_mul_ps(_mm_and_ps(far, abs_mask), widen));
    lo = _mm_max_ps(widened_near, lo);  // widened_near > lo ? widened_near : lo
    hi = _mm_min_ps(widened_far, hi);   // widened_far < hi ? widened_far : hi
  }
  _mm_storeu_ps(entry, lo);
  const __m128 ok = _mm_and_ps(_mm_cmple_ps(lo, hi), _mm_cmpge_ps(hi, _mm_set1_ps(min_exit)));
  return static_cast<uint32_t>(_mm_movemask_ps(ok));
#else
  uint32_t mask = 0;
  for (uint32_t k = 0; k < 4; ++k) {
    float lo = tmin, hi = tmax;
    for (int axis = 0; axis < 3; ++axis) {
      const float t0 = (lo_rows[axis * stride + k] - ray.origin[axis]) * ray.inverse_direction[axis];
      const float t1 = (hi_rows[axis * stride + k] - ray.origin[axis]) * ray.inverse_direction[axis];
      const float near = fmin_inline(t0, t1);
      const float far = fmax_inline(t0, t1);
      const float widened_near = near - std::fabs(near) * kSlabWiden;
      const float widened_far = far + std::fabs(far) * kSlabWiden;
      lo = widened_near > lo ? widened_near : lo;
      hi = widened_far < hi ? widened_far : hi;
    }
    entry[k] = lo;
    if (lo <= hi && hi >= min_exit) mask |= 1u << k;
  }
  return mask;
#endif
}

// Inserts `key` into the sorted window of up to N keys (keeping the N smallest).
template <std::size_t N>
inline void insert_key(const BrickKey& key, std::array<BrickKey, N>& window, uint32_t& found) {
  if (found == N && !(key < window[N - 1])) return;
  uint32_t pos = found < N ? found++ : N - 1;
  while (pos > 0 && key < window[pos - 1]) {
    window[pos] = window[pos - 1];
    --pos;
  }
  window[pos] = key;
}
}  // namespace detail

// next_bricks over a FlatLeaves: every leaf box gets the slab test at once
// (four per SSE instruction), no inner node is tested. The result is the same
// as next_bricks' on the hierarchy the leaves came from: each leaf's entry is
// computed by the same IEEE operations as detail::slab_test (bitwise equal
// keys), a leaf's box lies inside its ancestors' (an ancestor that fails
// its test has leaves that fail theirs), and next_bricks' tighter limit for a
// full window only skips leaves whose key could not enter it. What it saves
// is the inner nodes and a branch per node: about half the first upper pass
// on the 3-brick bunny.
template <std::size_t N>
uint32_t next_bricks_flat(const FlatLeaves& flat, const SlabRay& ray, float tmin, float tmax,
                          const BrickKey& after, std::array<BrickKey, N>& window, uint64_t& nodes_visited) {
  nodes_visited += flat.count;
  alignas(16) float entry[FlatLeaves::kMaxLeaves];
  uint32_t hit_mask = 0;
  for (uint32_t base = 0; base < flat.count; base += 4) {
    hit_mask |= detail::slab_test4(ray, &flat.lo[0][base], &flat.hi[0][base], FlatLeaves::kMaxLeaves, tmin,
                                   tmax, after.entry, &entry[base])
                << base;
  }
  hit_mask &= (1u << flat.count) - 1;
  uint32_t found = 0;
  while (hit_mask != 0) {
    const uint32_t j = static_cast<uint32_t>(__builtin_ctz(hit_mask));
    hit_mask &= hit_mask - 1;
    const BrickKey key{entry[j], flat.brick[j]};
    if (after < key) detail::insert_key(key, window, found);
  }
  return found;
}

// The upper hierarchy collapsed to W children per node (SoA boxes), for
// next_bricks_wide (W = 4, SSE) and next_bricks_wide8 (W = 8, AVX;
// upper_wide8_traversal.h): a fraction of the binary tree's nodes, each
// testing its W boxes in one SIMD operation and without a branch per box.
// Built from the binary tree once, when the engine opens.
template <uint32_t W>
struct WideUpperOf {
  struct Node {
    alignas(W * 4 > 32 ? 32 : W * 4) float lo[3][W];
    alignas(W * 4 > 32 ? 32 : W * 4) float hi[3][W];
    uint32_t child[W];  // a node index, or a brick id where bit k of leaf_bits is set
    uint32_t count = 0;
    uint32_t leaf_bits = 0;  // bit k: child k is a leaf
  };
  std::vector<Node> nodes;  // nodes[0] is the root
};
using WideUpper = WideUpperOf<4>;

// Collapses `upper` into `wide`: each wide node takes the children of a
// binary node and keeps opening its largest inner child (by surface area)
// until it has W.
template <uint32_t W>
void make_wide_upper(const UpperHierarchy& upper, WideUpperOf<W>& wide) {
  using Node = typename WideUpperOf<W>::Node;
  wide.nodes.clear();
  if (upper.nodes.empty()) return;
  std::vector<std::pair<uint32_t, uint32_t>> todo = {{0, 0}};  // (binary node, wide node)
  wide.nodes.emplace_back();
  auto area = [&](uint32_t b) {
    const Vec3f e = upper.nodes[b].bounds.extent();
    return e.x * e.y + e.y * e.z + e.z * e.x;
  };
  while (!todo.empty()) {
    const auto [binary, index] = todo.back();
    todo.pop_back();
    uint32_t kids[W];
    uint32_t count = 0;
    const UpperNode& node = upper.nodes[binary];
    if (node.is_leaf) {
      kids[count++] = binary;  // a one-brick hierarchy
    } else {
      kids[count++] = node.child_or_brick;
      kids[count++] = node.child_or_brick + 1;
    }
    while (count < W) {
      int open = -1;
      for (uint32_t k = 0; k < count; ++k) {
        if (!upper.nodes[kids[k]].is_leaf && (open < 0 || area(kids[k]) > area(kids[open]))) open = int(k);
      }
      if (open < 0) break;
      const uint32_t left = upper.nodes[kids[open]].child_or_brick;
      kids[open] = left;
      kids[count++] = left + 1;
    }
    Node wide_node;
    wide_node.count = count;
    for (uint32_t k = 0; k < W; ++k) {
      const Aabb box = k < count ? upper.nodes[kids[k]].bounds : Aabb();
      for (int axis = 0; axis < 3; ++axis) {
        wide_node.lo[axis][k] = k < count ? box.lo[axis] : 0.0f;  // unused lanes: computed, never reported
        wide_node.hi[axis][k] = k < count ? box.hi[axis] : 0.0f;
      }
      wide_node.child[k] = kInvalidId;
      if (k >= count) continue;
      if (upper.nodes[kids[k]].is_leaf) {
        wide_node.leaf_bits |= 1u << k;
        wide_node.child[k] = upper.nodes[kids[k]].child_or_brick;
      } else {
        wide_node.child[k] = static_cast<uint32_t>(wide.nodes.size());
        todo.emplace_back(kids[k], wide_node.child[k]);
        wide.nodes.emplace_back();
      }
    }
    wide.nodes[index] = wide_node;
  }
}

// next_bricks over a WideUpper: the same keys as next_bricks on the binary
// tree it came from (each leaf's entry from its own box by the same IEEE
// operations; the binary nodes a wide node skips only pruned what their
// leaves' own tests prune, as in next_bricks_flat). Counts tested boxes.
template <std::size_t N>
uint32_t next_bricks_wide(const WideUpper& wide, const SlabRay& ray, float tmin, float tmax,
                          const BrickKey& after, std::array<BrickKey, N>& window, uint64_t& nodes_visited) {
  uint32_t found = 0;
  if (wide.nodes.empty()) return 0;
  // Each level leaves at most three siblings pending.
  std::array<uint32_t, 3 * kMaxUpperDepth + 4> stack;
  uint32_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const WideUpper::Node& node = wide.nodes[stack[--top]];
    nodes_visited += node.count;
    // Once the window is full, only keys below its largest can enter.
    const float limit = found == N ? std::min(tmax, window[N - 1].entry) : tmax;
    alignas(16) float entry[4];
    uint32_t mask =
        detail::slab_test4(ray, &node.lo[0][0], &node.hi[0][0], 4, tmin, limit, after.entry, entry) &
        ((1u << node.count) - 1);
    while (mask != 0) {
      const uint32_t k = static_cast<uint32_t>(__builtin_ctz(mask));
      mask &= mask - 1;
      if (!(node.leaf_bits >> k & 1u)) {
        stack[top++] = node.child[k];
        continue;
      }
      const BrickKey key{entry[k], node.child[k]};
      if (after < key) detail::insert_key(key, window, found);
    }
  }
  return found;
}

}  // namespace outcore
