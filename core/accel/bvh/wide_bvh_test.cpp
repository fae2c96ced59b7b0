// The wide BVH against its simple reference: every SIMD path (SSE 4 lanes,
// AVX2 8 lanes where the CPU has it) and every triangle test must answer
// bitwise as the binary tree's scalar traversal (bvh_traversal.h) with the
// same test, closest hit and any hit, on scenes with shared edges, rays aimed
// at vertices and edges, rays in box planes and axis-parallel rays. And the
// collapse must keep every triangle exactly once, inside its boxes.
#include "core/accel/bvh/wide_bvh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/bvh/binned_sah_builder.h"
#include "core/accel/bvh/bvh_traversal.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/accel/bvh/wide_bvh_collapse.h"
#include "core/accel/bvh/wide_bvh_kernels.h"
#include "core/accel/bvh/wide_bvh_top_level.h"
#include "core/accel/bvh/wide_bvh_trace.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::all_ids;
using accel_test::bounds_of;
using accel_test::load_brick_from;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 500;
#else
constexpr std::size_t kRays = 4000;
#endif

// The binary tree (the reference) and its wide collapse, over the same
// usable triangles.
struct Trees {
  BvhTree binary;
  WideBvh wide;
};

Trees build_trees(const BrickData& brick, const BinnedSahBuilder::Config& config = {}) {
  std::vector<Triangle> triangles;
  std::vector<TriangleId> ids;
  for (std::size_t k = 0; k < brick.triangles.size(); ++k) {
    if (!brick.triangles[k].is_finite() || brick.triangles[k].is_degenerate()) continue;
    triangles.push_back(brick.triangles[k]);
    ids.push_back(brick.ids[k]);
  }
  BinnedSahBuilder::Result built = BinnedSahBuilder::build(triangles, config);
  Trees trees;
  trees.wide = WideBvhCollapser::collapse(built.nodes, built.order, triangles, ids).tree;
  trees.binary.nodes = built.nodes;
  for (const uint32_t k : built.order) {
    trees.binary.triangles.push_back(triangles[k]);
    trees.binary.records.push_back({triangles[k].unit_normal(), ids[k].geometry_id, ids[k].primitive_id});
  }
  return trees;
}

std::vector<SimdPath> supported_paths() {
  std::vector<SimdPath> paths;
  for (const SimdPath path : {SimdPath::kSse4, SimdPath::kAvx2}) {
    if (simd_path_supported(path)) paths.push_back(path);
  }
  return paths;
}

template <class Test>
void reference_answers(const BvhTree& tree, const std::vector<Ray>& rays, std::vector<Hit>& hits,
                       std::vector<uint8_t>& occluded) {
  for (std::size_t i = 0; i < rays.size(); ++i) {
    bvh_closest_hit<Test>(tree.view(), rays[i], hits[i]);
    occluded[i] = bvh_any_hit<Test>(tree.view(), rays[i]) ? 1 : 0;
  }
}

// Every path and test against the binary scalar reference, bitwise.
void expect_paths_match_reference(const std::string& what, const Trees& trees, const std::vector<Ray>& rays,
                                  std::size_t min_hits = 1) {
  ASSERT_TRUE(trees.wide.view().validate().ok()) << what;
  for (const TriangleTest test : kAllTriangleTests) {
    std::vector<Hit> want(rays.size());
    std::vector<uint8_t> want_occluded(rays.size(), 0);
    switch (test) {
      case TriangleTest::kMt:
        reference_answers<MtTriangleTest>(trees.binary, rays, want, want_occluded);
        break;
      case TriangleTest::kWatertight:
        reference_answers<WatertightTriangleTest>(trees.binary, rays, want, want_occluded);
        break;
      case TriangleTest::kDouble:
        reference_answers<DoubleTriangleTest>(trees.binary, rays, want, want_occluded);
        break;
    }
    const std::size_t hits = std::count_if(want.begin(), want.end(), [](const Hit& h) { return h.is_hit(); });
    EXPECT_GE(hits, min_hits) << what;
    for (const SimdPath path : supported_paths()) {
      const std::string name =
          what + " " + std::string(triangle_test_name(test)) + " " + std::string(simd_path_name(path));
      std::vector<Hit> got(rays.size());
      wide_bvh_intersect(path, test, trees.wide.view(), all_ids(rays.size()), rays.data(), got.data());
      std::size_t differ = 0;
      for (std::size_t i = 0; i < rays.size(); ++i) {
        if (std::memcmp(&got[i], &want[i], sizeof(Hit)) != 0 && differ++ < 5) {
          ADD_FAILURE() << name << " ray " << i << ": t " << got[i].t << " vs " << want[i].t << ", ids "
                        << got[i].geometry_id << "/" << got[i].primitive_id << " vs " << want[i].geometry_id
                        << "/" << want[i].primitive_id;
        }
      }
      EXPECT_EQ(differ, 0u) << name;
      std::vector<uint8_t> got_occluded(rays.size(), 0);
      wide_bvh_occluded(path, test, trees.wide.view(), all_ids(rays.size()), rays.data(),
                        got_occluded.data());
      EXPECT_EQ(got_occluded, want_occluded) << name;
    }
  }
}

std::vector<Ray> mixed_rays(const BrickData& brick, std::size_t n, uint64_t seed) {
  const Aabb b = bounds_of(brick);
  auto rays = accel_test::rays_from_outside(b, n / 2, seed);
  const auto inside = accel_test::rays_from_inside(b, n - n / 2, seed + 1);
  rays.insert(rays.end(), inside.begin(), inside.end());
  for (std::size_t i = 0; i < rays.size(); ++i) {
    if (i % 7 == 3) rays[i].tfar = 0.3f * length(b.extent());
    if (i % 11 == 5) rays[i].tnear = 0.05f * length(b.extent());
    if (i % 13 == 6) rays[i].tnear = -0.5f * length(b.extent());
  }
  return rays;
}

// Rays from an interior point aimed exactly at every vertex and edge
// midpoint (the stress suite's leak rays), and axis-parallel rays through
// vertices, which lie in box planes.
std::vector<Ray> aimed_rays(const BrickData& brick, const Vec3f& interior) {
  std::vector<Ray> rays;
  for (const Triangle& tri : brick.triangles) {
    const Vec3f targets[] = {tri.v0, tri.v1, tri.v2, (tri.v0 + tri.v1) * 0.5f, (tri.v1 + tri.v2) * 0.5f};
    for (const Vec3f& target : targets) {
      Ray ray;
      ray.origin = interior;
      ray.direction = target - interior;
      rays.push_back(ray);
    }
    for (int axis = 0; axis < 3; ++axis) {
      Ray ray;
      ray.origin = tri.v0;
      ray.origin[axis] -= 10.0f;
      ray.direction = {0, 0, 0};
      ray.direction[axis] = 1.0f;
      rays.push_back(ray);
    }
  }
  return rays;
}

TEST(WideBvh, EveryPathMatchesTheScalarReferenceOnGeneratedScenes) {
  for (const char* spec :
       {"gen:sphere?level=4", "gen:torus?nu=48&nv=24", "gen:terrain?n=24&size=6&height=0.5"}) {
    const BrickData brick = load_brick_from(spec);
    expect_paths_match_reference(spec, build_trees(brick), mixed_rays(brick, kRays, 11), kRays / 10);
  }
}

TEST(WideBvh, EveryPathMatchesTheScalarReferenceOnSoupsAndTheBunny) {
  const BrickData random = accel_test::random_triangles(1500, 4);
  expect_paths_match_reference("random", build_trees(random), mixed_rays(random, kRays, 12), kRays / 10);
  const BrickData scattered = accel_test::scattered_triangles(3000, 5);
  expect_paths_match_reference("scattered", build_trees(scattered), mixed_rays(scattered, kRays, 13));
  const BrickData degenerate = accel_test::degenerate_heavy(3000, 6);
  expect_paths_match_reference("degenerate", build_trees(degenerate), mixed_rays(degenerate, kRays, 14));
  const BrickData bunny = load_brick_from(accel_test::bunny_path());
  expect_paths_match_reference("bunny", build_trees(bunny), mixed_rays(bunny, kRays, 15), kRays / 10);
}

TEST(WideBvh, EveryPathMatchesTheScalarReferenceOnAimedAndAxisRays) {
  // Closed meshes, hit exactly at vertices and edges from inside, near the
  // origin and far from it.
  for (const float offset : {0.0f, 1e5f}) {
    BrickData sphere = load_brick_from("gen:sphere?level=2");
    for (Triangle& tri : sphere.triangles) {
      for (Vec3f* v : {&tri.v0, &tri.v1, &tri.v2}) v->x += offset;
    }
    const Aabb b = bounds_of(sphere);
    const std::vector<Ray> rays = aimed_rays(sphere, b.center() + Vec3f(0.01f, 0.02f, -0.03f));
    expect_paths_match_reference("aimed sphere +" + std::to_string(offset), build_trees(sphere), rays,
                                 rays.size() / 2);
  }
  // A grid terrain: many boxes share planes with the axis-parallel rays.
  const BrickData terrain = load_brick_from("gen:terrain?n=16&size=4&height=0");
  const std::vector<Ray> rays = aimed_rays(terrain, bounds_of(terrain).center() + Vec3f(0.01f, 1, 1));
  expect_paths_match_reference("flat terrain", build_trees(terrain), rays, rays.size() / 4);
}

// A pinhole camera's rays in pixel order (one origin, directions that vary
// smoothly): the runs the packet walk takes, with a few rays that break a
// run (another origin, a shorter tfar, a tnear, a zero component).
std::vector<Ray> camera_rays(const BrickData& brick, uint32_t side, const Vec3f& eye_offset) {
  const Aabb b = bounds_of(brick);
  const Vec3f eye = b.center() + eye_offset;
  std::vector<Ray> rays;
  for (uint32_t y = 0; y < side; ++y) {
    for (uint32_t x = 0; x < side; ++x) {
      const float fx = (static_cast<float>(x) + 0.5f) / static_cast<float>(side);
      const float fy = (static_cast<float>(y) + 0.5f) / static_cast<float>(side);
      const Vec3f target(b.lo.x + fx * (b.hi.x - b.lo.x), b.lo.y + fy * (b.hi.y - b.lo.y), b.center().z);
      Ray ray;
      ray.origin = eye;
      ray.direction = target - eye;
      const std::size_t i = rays.size();
      if (i % 97 == 13) ray.origin.x += 1e-3f;
      if (i % 89 == 7) ray.tfar = 0.5f;
      if (i % 83 == 5) ray.tnear = 0.9f;
      if (i % 101 == 3) ray.direction.x = 0.0f;
      rays.push_back(ray);
    }
  }
  return rays;
}

TEST(WideBvh, CameraRunsTracedAsPacketsMatchTheScalarReference) {
  const BrickData bunny = load_brick_from(accel_test::bunny_path());
  const float reach = length(bounds_of(bunny).extent());
  const auto side = static_cast<uint32_t>(std::sqrt(static_cast<double>(kRays)));
  // Looking down each axis and from a corner, so every permutation occurs.
  for (const Vec3f& offset : {Vec3f(0, 0, 2 * reach), Vec3f(0, 0, -2 * reach), Vec3f(2 * reach, 0.1f, 0.2f),
                              Vec3f(0.1f, -2 * reach, 0.3f), Vec3f(reach, reach, reach)}) {
    const std::vector<Ray> rays = camera_rays(bunny, side, offset);
    expect_paths_match_reference("bunny camera", build_trees(bunny), rays, rays.size() / 10);
  }
  const BrickData sphere = load_brick_from("gen:sphere?level=4");
  const std::vector<Ray> inside = camera_rays(sphere, side, Vec3f(0.01f, 0.02f, 0.03f));  // from inside
  expect_paths_match_reference("sphere from inside", build_trees(sphere), inside, inside.size() / 2);
}

// The single-ray walks of one call are interleaved
// (wide_bvh_stepped_kernels.h): each ray's answer (closest hit and occlusion)
// must not depend on which rays share the call. Lists of every length up to
// a few walks, a ray listed twice, rays already answered (a hit nearer than
// anything here, or occluded) between rays that walk, and camera runs
// (packets) between single rays, against the ray traced alone, on every path
// and test.
TEST(WideBvh, InterleavedWalksAnswerEachRayAsIfTracedAlone) {
  const BrickData bunny = load_brick_from(accel_test::bunny_path());
  const Trees trees = build_trees(bunny);
  std::vector<Ray> rays = mixed_rays(bunny, 120, 31);
  const std::vector<Ray> camera = camera_rays(bunny, 6, Vec3f(0, 0, 2 * length(bounds_of(bunny).extent())));
  rays.insert(rays.begin() + 40, camera.begin(), camera.begin() + 20);
  std::vector<Hit> earlier(rays.size());
  for (std::size_t i = 0; i < rays.size(); i += 5) earlier[i].t = 1e-30f;  // answered: nothing nearer here
  for (const SimdPath path : supported_paths()) {
    for (const TriangleTest test : kAllTriangleTests) {
      const std::string name =
          std::string(triangle_test_name(test)) + " " + std::string(simd_path_name(path));
      std::vector<Hit> alone = earlier;
      std::vector<uint8_t> alone_occluded(rays.size(), 0);
      for (uint32_t i = 0; i < rays.size(); ++i) {
        const std::span<const uint32_t> one(&i, 1);
        wide_bvh_intersect(path, test, trees.wide.view(), one, rays.data(), alone.data());
        if (i % 7 == 2) alone_occluded[i] = 1;  // found occluded in an earlier brick
        wide_bvh_occluded(path, test, trees.wide.view(), one, rays.data(), alone_occluded.data());
      }
      EXPECT_GT(std::count(alone_occluded.begin(), alone_occluded.end(), 0), 0) << name;
      const std::size_t hits =
          std::count_if(alone.begin(), alone.end(), [](const Hit& h) { return h.is_hit(); });
      EXPECT_GE(hits, rays.size() / 4) << name;
      for (std::size_t count = 1; count <= 9; ++count) {
        for (std::size_t first = 0; first + count <= rays.size(); first += count) {
          std::vector<uint32_t> ids(count);
          for (std::size_t k = 0; k < count; ++k) ids[k] = static_cast<uint32_t>(first + k);
          if (count >= 3) ids[count - 1] = ids[0];  // listed twice
          std::vector<Hit> got = earlier;
          wide_bvh_intersect(path, test, trees.wide.view(), ids, rays.data(), got.data());
          std::vector<uint8_t> occluded(rays.size(), 0);
          for (const uint32_t i : ids) occluded[i] = i % 7 == 2;
          wide_bvh_occluded(path, test, trees.wide.view(), ids, rays.data(), occluded.data());
          for (const uint32_t i : ids) {
            ASSERT_EQ(std::memcmp(&got[i], &alone[i], sizeof(Hit)), 0)
                << name << " ray " << i << " in a list of " << count << " from " << first << ": t "
                << got[i].t << " vs " << alone[i].t;
            ASSERT_EQ(occluded[i], alone_occluded[i])
                << name << " occlusion of ray " << i << " in a list of " << count << " from " << first;
          }
        }
      }
    }
  }
}

// Packets culled by their whole-packet bounds (interval and slope) and
// packets whose large boxes skip the lane-by-lane test must still find every
// vertex and edge hit: runs of eight rays from one interior point, each run
// aimed at the vertices and edge midpoints of neighbouring triangles of a
// closed sphere, near the origin and at offsets up to 1e6 (the sphere
// scaled with the offset so that its triangles stay usable in float).
TEST(WideBvh, PacketsAimedAtVerticesAndEdgesOfAClosedMeshLeakNothingAtAnyOffset) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    BrickData sphere = load_brick_from("gen:sphere?level=3");
    const float scale = std::max(1.0f, offset * 1e-3f);
    for (Triangle& tri : sphere.triangles) {
      for (Vec3f* v : {&tri.v0, &tri.v1, &tri.v2}) *v = *v * scale + Vec3f(offset, -0.5f * offset, offset);
    }
    const Vec3f interior = bounds_of(sphere).center() + Vec3f(0.01f, 0.02f, -0.03f) * scale;
    std::vector<Ray> rays;
    for (const Triangle& tri : sphere.triangles) {
      for (const Vec3f& target : {tri.v0, tri.v1, tri.v2, (tri.v0 + tri.v1) * 0.5f, (tri.v1 + tri.v2) * 0.5f,
                                  (tri.v2 + tri.v0) * 0.5f, (tri.v0 + tri.v1 + tri.v2) / 3.0f, tri.v0}) {
        Ray ray;
        ray.origin = interior;
        ray.direction = target - interior;
        rays.push_back(ray);
      }
    }
    const std::string what = "packets aimed at a sphere +" + std::to_string(offset);
    const Trees trees = build_trees(sphere);
    expect_paths_match_reference(what, trees, rays, rays.size() / 2);  // mt may leak; watertight below
    for (const SimdPath path : supported_paths()) {
      std::vector<Hit> got(rays.size());
      wide_bvh_intersect(path, TriangleTest::kWatertight, trees.wide.view(), all_ids(rays.size()),
                         rays.data(), got.data());
      const auto leaks = std::count_if(got.begin(), got.end(), [](const Hit& h) { return !h.is_hit(); });
      EXPECT_EQ(leaks, 0) << what << " " << simd_path_name(path);
    }
  }
}

// A set of many trees (the bunny cut into slabs, one tree each) walked
// through its top level answers bitwise as the trees traced one after the
// other with the best hit carried: every path, every test, camera runs and
// single rays.
TEST(WideBvh, ASetOfManyTreesAnswersAsItsTreesOneByOne) {
  const BrickData bunny = load_brick_from(accel_test::bunny_path());
  std::vector<std::size_t> order(bunny.triangles.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  const auto centre_x = [&](std::size_t k) {
    const Triangle& t = bunny.triangles[k];
    return t.v0.x + t.v1.x + t.v2.x;
  };
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return centre_x(a) < centre_x(b); });
  constexpr std::size_t kSlabs = 300;
  std::vector<WideBvh> trees;
  std::vector<WideBvhView> views;
  std::vector<Aabb> bounds;
  for (std::size_t s = 0; s < kSlabs; ++s) {
    BrickData slab;
    for (std::size_t j = s * order.size() / kSlabs; j < (s + 1) * order.size() / kSlabs; ++j) {
      slab.triangles.push_back(bunny.triangles[order[j]]);
      slab.ids.push_back(bunny.ids[order[j]]);
    }
    trees.push_back(build_trees(slab).wide);
    bounds.push_back(bounds_of(slab));
  }
  for (const WideBvh& tree : trees) views.push_back(tree.view());
  const std::vector<WideBvhNode> top = build_wide_top_level(bounds);
  const WideBvhSetView set{views, top};

  const float reach = length(bounds_of(bunny).extent());
  std::vector<Ray> rays = camera_rays(bunny, 48, Vec3f(0.1f, 0.2f, 2 * reach));
  const std::vector<Ray> mixed = mixed_rays(bunny, kRays / 2, 21);
  rays.insert(rays.end(), mixed.begin(), mixed.end());
  const std::vector<uint32_t> ids = all_ids(rays.size());
  for (const TriangleTest test : kAllTriangleTests) {
    for (const SimdPath path : supported_paths()) {
      const std::string name =
          std::string(triangle_test_name(test)) + " " + std::string(simd_path_name(path));
      std::vector<Hit> want(rays.size()), got(rays.size());
      std::vector<uint8_t> want_occluded(rays.size(), 0), got_occluded(rays.size(), 0);
      for (const WideBvhView& tree : views) {
        wide_bvh_intersect(path, test, tree, ids, rays.data(), want.data());
        wide_bvh_occluded(path, test, tree, ids, rays.data(), want_occluded.data());
      }
      wide_bvh_set_intersect(path, test, set, ids, rays.data(), got.data());
      wide_bvh_set_occluded(path, test, set, ids, rays.data(), got_occluded.data());
      std::size_t differ = 0, hits = 0;
      for (std::size_t i = 0; i < rays.size(); ++i) {
        hits += want[i].is_hit();
        if (std::memcmp(&got[i], &want[i], sizeof(Hit)) != 0 && differ++ < 5) {
          ADD_FAILURE() << name << " ray " << i << ": t " << got[i].t << " vs " << want[i].t;
        }
      }
      EXPECT_EQ(differ, 0u) << name;
      EXPECT_GT(hits, rays.size() / 10) << name;
      EXPECT_EQ(got_occluded, want_occluded) << name;
    }
  }
}

TEST(WideBvh, LeavesOfEveryShapeAndSize) {
  // Tiny trees (one leaf, a partial packet), leaves larger than a packet
  // (max_leaf_size 32 spans several packets and starts mid-packet), and one
  // triangle per leaf.
  const BrickData sphere = load_brick_from("gen:sphere?level=3");
  for (const std::size_t n : {1, 2, 7, 8, 9, 17}) {
    const BrickData small = accel_test::resized(sphere, n);
    expect_paths_match_reference("sphere of " + std::to_string(n), build_trees(small),
                                 mixed_rays(small, 400, n));
  }
  for (const uint32_t leaf : {1u, 3u, 32u}) {
    BinnedSahBuilder::Config config;
    config.max_leaf_size = leaf;
    config.intersection_cost = leaf == 32 ? 0.05f : 1.0f;  // big leaves when allowed
    expect_paths_match_reference("leaf " + std::to_string(leaf), build_trees(sphere, config),
                                 mixed_rays(sphere, 1000, leaf), 100);
  }
}

TEST(WideBvh, CollapseKeepsEveryTriangleOnceInsideItsBoxes) {
  const BrickData brick = load_brick_from("gen:torus?nu=64&nv=32");
  for (const uint32_t leaf : {1u, 8u, 32u}) {
    BinnedSahBuilder::Config config;
    config.max_leaf_size = leaf;
    const WideBvh wide = build_trees(brick, config).wide;
    ASSERT_TRUE(wide.view().validate().ok());
    std::vector<uint32_t> seen(brick.triangles.size(), 0);
    std::vector<uint8_t> slot_used(wide.packets.size() * kPacketLanes, 0);
    // Walk: every leaf's triangles inside the leaf's box, every inner
    // child's boxes inside the parent's box for it.
    struct Item {
      uint32_t node;
      Aabb box;
    };
    std::vector<Item> stack{{0, Aabb{{-1e30f, -1e30f, -1e30f}, {1e30f, 1e30f, 1e30f}}}};
    while (!stack.empty()) {
      const Item item = stack.back();
      stack.pop_back();
      const WideBvhNode& node = wide.nodes[item.node];
      for (uint32_t k = 0; k < kWideBvhWidth; ++k) {
        const Aabb box = node.box(k);
        if ((node.child_mask() >> k & 1) == 0) {
          EXPECT_TRUE(box.empty()) << "empty child slot " << k;
          continue;
        }
        EXPECT_TRUE(item.box.contains(box)) << "node " << item.node << " child " << k;
        if (node.inner_mask >> k & 1) {
          stack.push_back({node.child[k], box});
          continue;
        }
        for (uint32_t s = node.child[k]; s < node.child[k] + node.leaf_triangles[k]; ++s) {
          const TrianglePacket& packet = wide.packets[s / kPacketLanes];
          const uint32_t lane = s % kPacketLanes;
          ASSERT_LT(packet.primitive_id[lane], seen.size());
          ++seen[packet.primitive_id[lane]];
          ++slot_used[s];
          const Triangle tri = packet.triangle(lane);
          EXPECT_TRUE(box.contains(tri.bounds())) << "slot " << s;
          EXPECT_EQ(tri, brick.triangles[packet.primitive_id[lane]]);
        }
      }
    }
    for (std::size_t k = 0; k < seen.size(); ++k)
      ASSERT_EQ(seen[k], 1u) << "triangle " << k << " leaf " << leaf;
    // Padding: unused slots carry no ids, and stay within a quarter of n.
    std::size_t padding = 0;
    for (std::size_t s = 0; s < slot_used.size(); ++s) {
      if (slot_used[s]) continue;
      ++padding;
      EXPECT_EQ(wide.packets[s / kPacketLanes].geometry_id[s % kPacketLanes], kInvalidId);
    }
    EXPECT_LE(padding, brick.triangles.size() / 4 + kPacketLanes) << "leaf " << leaf;
    EXPECT_LE(wide.nodes.size() * sizeof(WideBvhNode) + wide.packets.size() * sizeof(TrianglePacket),
              WideBvhCollapser::peak_bytes_bound(brick.triangles.size()));
  }
}

TEST(WideBvh, SimdPathComesFromTheEnvironment) {
  EXPECT_TRUE(simd_path_supported(SimdPath::kSse4));
  ::setenv("OUTCORE_SIMD", "sse4", 1);
  auto chosen = simd_path_from_environment();
  ASSERT_TRUE(chosen.ok());
  EXPECT_EQ(*chosen, SimdPath::kSse4);
  ::setenv("OUTCORE_SIMD", "avx512", 1);
  chosen = simd_path_from_environment();
  ASSERT_FALSE(chosen.ok());
  EXPECT_NE(chosen.status().message().find("avx512"), std::string::npos);
  ::unsetenv("OUTCORE_SIMD");
  chosen = simd_path_from_environment();
  ASSERT_TRUE(chosen.ok());
  EXPECT_EQ(*chosen, simd_path_supported(SimdPath::kAvx2) ? SimdPath::kAvx2 : SimdPath::kSse4);
}

// The walks push a node's entered children at push_position: the order must
// be the stable sort of the entries, farthest at the bottom, ties by index.
TEST(WideBvh, PushPositionsOrderChildrenFarthestFirstTiesByIndex) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> value(0, 4);  // few values: many ties
  for (int trial = 0; trial < 2000; ++trial) {
    alignas(32) float entry[kWideBvhWidth];
    for (float& e : entry) e = trial % 3 == 0 ? -static_cast<float>(value(rng)) : 0.5f * value(rng);
    const uint32_t mask = static_cast<uint32_t>(rng()) & 0xffu;
    std::vector<uint32_t> reference;
    for (uint32_t k = 0; k < kWideBvhWidth; ++k)
      if (mask >> k & 1u) reference.push_back(k);
    std::stable_sort(reference.begin(), reference.end(),
                     [&](uint32_t a, uint32_t b) { return entry[a] > entry[b]; });
    for (uint32_t position = 0; position < reference.size(); ++position) {
      EXPECT_EQ(wide_kernels::push_position<SimdLanes4>(entry, mask, reference[position]), position)
          << "trial " << trial << ", child " << reference[position];
    }
  }
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
