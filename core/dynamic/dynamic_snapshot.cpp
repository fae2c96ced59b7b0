#include "core/dynamic/dynamic_snapshot.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <cmath>
#include <limits>

#include "core/accel/bvh/triangle_test_kind.h"
#include "core/accel/bvh/wide_bvh_refit.h"
#include "core/accel/bvh/wide_bvh_top_level.h"
#include "core/accel/bvh/wide_bvh_trace.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_problem.h"

namespace outcore {
namespace {

constexpr std::size_t kRaysPerTask = 1024;
// Enough for any top level build_wide_top_level makes (median splits: depth
// about log8 of the instances; 7 entries pushed a level).
constexpr std::size_t kTopStack = 512;

// The ray in double with its world-box slack.
struct WorldRay {
  Vec3d origin, direction;
  double pad = 0;
};

WorldRay world_ray(const Ray& ray, double slack, double scene_magnitude) {
  WorldRay r{Vec3d(ray.origin), Vec3d(ray.direction), 0};
  r.pad = slack * (max_abs(r.origin) + scene_magnitude) + std::numeric_limits<float>::denorm_min();
  return r;
}

// Clips [t0, t1] to the part of the ray inside the box widened by the ray's
// pad; false when nothing is left.
bool clip(const WorldRay& r, const Aabb& box, double& t0, double& t1) {
  for (int a = 0; a < 3; ++a) {
    const double lo = static_cast<double>(box.lo[a]) - r.pad, hi = static_cast<double>(box.hi[a]) + r.pad;
    const double o = r.origin[a], d = r.direction[a];
    if (d == 0.0) {
      if (o < lo || o > hi) return false;
      continue;
    }
    double near = (lo - o) / d, far = (hi - o) / d;
    if (near > far) std::swap(near, far);
    t0 = std::max(t0, near);
    t1 = std::min(t1, far);
    if (t0 > t1) return false;
  }
  return true;
}

// Whether the ray may meet the box, widened by the ray's pad, within [t0, t1].
bool may_enter(const WorldRay& r, const Aabb& box, double t0, double t1) {
  return clip(r, box, t0, t1);
}

// Calls visit(instance index) for every instance whose widened world box the
// ray may meet within [tnear, limit()] (limit re-read as hits shrink it).
template <typename Limit, typename Visit>
void walk_top(const DynamicSnapshot& s, const WorldRay& r, double tnear, const Limit& limit,
              const Visit& visit) {
  if (s.top.empty()) return;
  std::array<uint32_t, kTopStack> stack;
  std::size_t depth = 0;
  stack[depth++] = 0;
  while (depth > 0) {
    const WideBvhNode& node = s.top[stack[--depth]];
    const uint8_t used = node.child_mask();
    for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
      if (!((used >> k) & 1u) || !may_enter(r, node.box(k), tnear, limit())) continue;
      if ((node.inner_mask >> k) & 1u) {
        assert(depth < kTopStack);
        stack[depth++] = node.child[k];
      } else if (!visit(node.child[k])) {
        return;
      }
    }
  }
}

// The B-KD tree's walk: each node clips the ray's interval to its children's
// slabs along its axis; a leaf's instance is visited when the ray may meet
// its whole box.
template <typename Limit, typename Visit>
void walk_bkd(const DynamicSnapshot& s, const WorldRay& r, double tnear, const Limit& limit,
              const Visit& visit) {
  const std::vector<BkdNode>& nodes = s.bkd.nodes();
  if (nodes.empty()) return;
  struct Entry {
    uint32_t node;
    double t0, t1;
  };
  // Clipped to the whole tree's box first.
  double t0 = tnear, t1 = limit();
  if (!clip(r, s.bkd.bounds(), t0, t1)) return;
  std::array<Entry, BkdTree::kMaxDepth + 2> stack;
  std::size_t depth = 0;
  stack[depth++] = {0, t0, t1};
  while (depth > 0) {
    const Entry e = stack[--depth];
    if (e.t0 > limit()) continue;
    const BkdNode& node = nodes[e.node];
    const double o = r.origin[node.axis], d = r.direction[node.axis];
    Entry kids[2];
    bool live[2] = {false, false};
    for (int c = 0; c < 2; ++c) {
      const double lo = static_cast<double>(node.lo[c]) - r.pad, hi = static_cast<double>(node.hi[c]) + r.pad;
      double t0 = e.t0, t1 = std::min(e.t1, limit());
      if (d == 0.0) {
        if (o < lo || o > hi) continue;
      } else {
        double near = (lo - o) / d, far = (hi - o) / d;
        if (near > far) std::swap(near, far);
        t0 = std::max(t0, near);
        t1 = std::min(t1, far);
      }
      if (t0 > t1) continue;
      if ((node.leaf_mask >> c) & 1u) {
        const uint32_t instance = node.child[c];
        if (c == 1 && node.child[0] == instance && ((node.leaf_mask & 1u) != 0)) continue;  // one instance
        if (may_enter(r, s.instances[instance].world_box, tnear, limit()) && !visit(instance)) return;
      } else {
        kids[c] = {node.child[c], t0, t1};
        live[c] = true;
      }
    }
    // The nearer child on top of the stack.
    const int first = live[0] && live[1] ? (kids[0].t0 <= kids[1].t0 ? 0 : 1) : (live[0] ? 0 : 1);
    if (live[1 - first]) {
      assert(depth < stack.size());
      stack[depth++] = kids[1 - first];
    }
    if (live[first]) {
      assert(depth < stack.size());
      stack[depth++] = kids[first];
    }
  }
}

template <typename Limit, typename Visit>
void walk_instances(const DynamicSnapshot& s, const WorldRay& r, double tnear, const Limit& limit,
                    const Visit& visit) {
  if (s.top_kind == DynamicTopLevel::kBkd) {
    walk_bkd(s, r, tnear, limit, visit);
  } else {
    walk_top(s, r, tnear, limit, visit);
  }
}

double scene_magnitude(const DynamicSnapshot& s) {
  Aabb box;
  for (const DynamicInstance& instance : s.instances) box.extend(instance.world_box);
  if (box.empty()) return 0;
  return std::max(max_abs(Vec3d(box.lo)), max_abs(Vec3d(box.hi)));
}

double max_slack(const DynamicSnapshot& s) {
  double slack = 0;
  for (const DynamicInstance& instance : s.instances) slack = std::max(slack, instance.slack);
  return slack;
}

// Runs body(i) for every valid ray (invalid ones are misses, as in the
// static scene), in parallel chunks; returns how many calls returned true.
template <typename Body>
uint64_t for_valid_rays(std::span<const Ray> rays, const Body& body) {
  std::atomic<uint64_t> count{0};
  tbb::parallel_for(std::size_t{0}, (rays.size() + kRaysPerTask - 1) / kRaysPerTask, [&](std::size_t c) {
    const std::size_t end = std::min(rays.size(), (c + 1) * kRaysPerTask);
    uint64_t chunk = 0;
    for (std::size_t i = c * kRaysPerTask; i < end; ++i)
      if (ray_is_valid(rays[i])) chunk += body(i);
    count.fetch_add(chunk, std::memory_order_relaxed);
  });
  return count.load();
}

}  // namespace

uint64_t DynamicSnapshot::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
  assert(hits.size() >= rays.size());
  if (instances.empty()) return 0;
  const double slack = max_slack(*this), magnitude = scene_magnitude(*this);
  const SimdPath path = active_simd_path();
  return for_valid_rays(rays, [&](std::size_t i) {
    const Ray& ray = rays[i];
    Hit& best = hits[i];
    const bool was_hit = best.is_hit();
    const WorldRay r = world_ray(ray, slack, magnitude);
    const auto limit = [&] { return std::min(static_cast<double>(ray.tfar), static_cast<double>(best.t)); };
    walk_instances(*this, r, ray.tnear, limit, [&](uint32_t index) {
      const DynamicInstance& instance = instances[index];
      Ray local = instance.to_object.ray_to_object(ray);
      local.tfar = std::min(ray.tfar, best.t);
      Hit hit;
      const uint32_t id = 0;
      wide_bvh_intersect(path, TriangleTest::kWatertight, meshes[instance.mesh_id]->view(), {&id, 1}, &local,
                         &hit);
      if (hit.is_hit() && hit_is_better(hit.t, instance.geometry_id, hit.primitive_id, best)) {
        hit.geometry_id = instance.geometry_id;
        hit.normal = instance.to_object.normal_to_world(hit.normal);
        best = hit;
      }
      return true;
    });
    return !was_hit && best.is_hit();
  });
}

uint64_t DynamicSnapshot::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
  assert(occluded.size() >= rays.size());
  if (instances.empty()) return 0;
  const double slack = max_slack(*this), magnitude = scene_magnitude(*this);
  const SimdPath path = active_simd_path();
  return for_valid_rays(rays, [&](std::size_t i) {
    const Ray& ray = rays[i];
    if (occluded[i] != 0) return false;
    const WorldRay r = world_ray(ray, slack, magnitude);
    const auto limit = [&] { return static_cast<double>(ray.tfar); };
    walk_instances(*this, r, ray.tnear, limit, [&](uint32_t index) {
      const DynamicInstance& instance = instances[index];
      const Ray local = instance.to_object.ray_to_object(ray);
      const uint32_t id = 0;
      uint8_t hit = 0;
      wide_bvh_occluded(path, TriangleTest::kWatertight, meshes[instance.mesh_id]->view(), {&id, 1}, &local,
                        &hit);
      occluded[i] = hit;
      return hit == 0;
    });
    return occluded[i] != 0;
  });
}

const DynamicInstance* DynamicSnapshot::find(uint32_t geometry_id) const {
  const auto it = std::lower_bound(instances.begin(), instances.end(), geometry_id,
                                   [](const DynamicInstance& i, uint32_t id) { return i.geometry_id < id; });
  return it != instances.end() && it->geometry_id == geometry_id ? &*it : nullptr;
}

uint64_t DynamicSnapshot::triangle_count() const {
  uint64_t n = 0;
  for (const DynamicInstance& instance : instances) n += meshes[instance.mesh_id]->triangle_count();
  return n;
}

uint64_t DynamicSnapshot::memory_bytes() const {
  uint64_t bytes = sizeof(*this) + instances.capacity() * sizeof(DynamicInstance) +
                   top.capacity() * sizeof(WideBvhNode) + meshes.capacity() * sizeof(meshes[0]);
  for (const auto& mesh : meshes)
    if (mesh != nullptr) bytes += mesh->memory_bytes();
  return bytes;
}

namespace {

std::vector<Aabb> world_boxes(const DynamicSnapshot& s) {
  std::vector<Aabb> boxes(s.instances.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) boxes[i] = s.instances[i].world_box;
  return boxes;
}

void build_top_level_over(DynamicSnapshot& snapshot, std::span<const Aabb> boxes) {
  if (snapshot.top_kind == DynamicTopLevel::kBkd) {
    snapshot.top.clear();
    snapshot.bkd = BkdTree::build(boxes);
    snapshot.top_built_cost = snapshot.bkd.cost(boxes);
  } else {
    snapshot.bkd = BkdTree();
    snapshot.top = build_wide_top_level(boxes);
    snapshot.top_built_cost = wide_bvh_sah_cost(snapshot.top);
  }
}

}  // namespace

void build_dynamic_top_level(DynamicSnapshot& snapshot) {
  build_top_level_over(snapshot, world_boxes(snapshot));
}

bool refit_dynamic_top_level(DynamicSnapshot& snapshot) {
  const std::vector<Aabb> boxes = world_boxes(snapshot);
  double cost = 0;
  if (snapshot.top_kind == DynamicTopLevel::kBkd) {
    snapshot.bkd.refit(boxes);
    cost = snapshot.bkd.cost(boxes);
  } else {
    refit_wide_top_level(snapshot.top, boxes);
    cost = wide_bvh_sah_cost(snapshot.top);
  }
  if (cost <= kTopLevelRebuildRatio * snapshot.top_built_cost) return false;
  build_top_level_over(snapshot, boxes);
  return true;
}

}  // namespace outcore
