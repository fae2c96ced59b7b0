// The kd-tree against brute force with the same triangle test (bitwise: the
// walk may only change which triangles are tested, never the answer), on
// generated scenes, soups, the bunny, rays aimed at a closed mesh's vertices
// and edges from inside at offsets up to 1e6 (0 leaks with the watertight
// test), and rays lying in or crossing exactly at the tree's split planes; the
// walk itself on a hand-built tree (the order of cells, the stack, and a
// triangle spanning two cells that must not end the walk early); the build's
// structure (validate, every triangle referenced, budgets) and the factory.
#include "core/accel/kdtree/kd_tree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_accel_factory.h"
#include "core/accel/bvh/double_triangle_test.h"
#include "core/accel/bvh/mt_triangle_test.h"
#include "core/accel/bvh/watertight_triangle_test.h"
#include "core/accel/kdtree/kd_tree_brick.h"
#include "core/accel/kdtree/kd_tree_builder.h"
#include "core/accel/kdtree/kd_tree_traversal.h"
#include "core/accel/kdtree/split_tree_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using accel_test::bounds_of;
using accel_test::load_brick_from;
using split_tree_test::brute_force;
using split_tree_test::mixed_rays;

#ifdef OUTCORE_SANITIZE_BUILD
constexpr std::size_t kRays = 400;
#else
constexpr std::size_t kRays = 3000;
#endif

KdTree build_tree(const BrickData& brick, const KdTreeBuilder::Config& config = {}) {
  const BrickData kept = split_tree_test::usable(brick);
  return KdTreeBuilder::build(kept.triangles, kept.ids, config).tree;
}

// The tree's walks, for the shared helpers (split_tree_test_util.h).
struct KdWalks {
  template <class Test>
  static bool closest(const KdTreeView& view, const Ray& ray, Hit& hit) {
    return kd_closest_hit<Test>(view, ray, hit);
  }
  template <class Test>
  static bool any(const KdTreeView& view, const Ray& ray) {
    return kd_any_hit<Test>(view, ray);
  }
};

template <class Node>
void expect_every_test_matches(const std::string& what, const SplitTree<Node>& tree,
                               const std::vector<Ray>& rays, std::size_t min_hits) {
  split_tree_test::expect_every_test_matches<KdWalks>(what, tree, rays, min_hits);
}

TEST(KdTree, MatchesBruteForceOnGeneratedScenesSoupsAndTheBunny) {
  split_tree_test::expect_every_test_matches_on_the_usual_scenes<KdWalks>(
      [](const BrickData& brick) { return build_tree(brick); }, kRays);
}

TEST(KdTree, AimedAtVerticesAndEdgesOfAClosedMeshItLeaksNothingAtAnyOffset) {
  for (const float offset : {0.0f, 1e3f, 1e6f}) {
    const auto [sphere, rays] = split_tree_test::aimed_sphere(offset);
    const KdTree tree = build_tree(sphere);
    const std::string what = "aimed sphere +" + std::to_string(offset);
    expect_every_test_matches(what, tree, rays, rays.size());
    std::size_t leaks = 0;
    for (const Ray& ray : rays) {
      Hit hit;
      leaks += !kd_closest_hit<WatertightTriangleTest>(tree.view(), ray, hit);
    }
    EXPECT_EQ(leaks, 0u) << what;
  }
}

// Rays in the tree's own split planes (parallel, origin on the plane) and
// rays crossing a split plane exactly at a vertex lying on it.
TEST(KdTree, RaysInAndThroughSplitPlanesLoseNothing) {
  for (const char* spec : {"gen:terrain?n=16&size=4&height=0", "gen:sphere?level=3"}) {
    const BrickData brick = load_brick_from(spec);
    const KdTree tree = build_tree(brick);
    const Aabb b = bounds_of(brick);
    std::vector<Ray> rays;
    for (const KdNode& node : tree.nodes) {
      if (node.is_leaf()) continue;
      const int axis = node.axis();
      for (int other = 0; other < 3; ++other) {
        if (other == axis) continue;
        Ray in_plane;
        in_plane.origin = b.center();
        in_plane.origin[axis] = node.split();
        in_plane.origin[other] = b.lo[other] - 1.0f;
        in_plane.direction = {0, 0, 0};
        in_plane.direction[other] = 1.0f;
        rays.push_back(in_plane);
      }
      for (const Triangle& tri : brick.triangles) {
        for (const Vec3f& v : {tri.v0, tri.v1, tri.v2}) {
          if (v[axis] != node.split() || rays.size() > 20 * tree.nodes.size()) continue;
          Ray through;
          through.origin = b.center() + Vec3f(0.3f, 0.7f, 0.2f) * length(b.extent());
          through.direction = v - through.origin;
          rays.push_back(through);
        }
      }
    }
    ASSERT_GT(rays.size(), 10u) << spec;
    expect_every_test_matches(std::string(spec) + " split planes", tree, rays, 1);
  }
}

// A hand-built tree: the root splits x at 0 (leaf A below), its upper child
// splits y at 0 (leaf B below, leaf C above). A ray from (-2, -2.5, 0) along
// (1, 1, 0) crosses x = 0 at t = 2 and y = 0 at t = 2.5: it must visit A, B,
// C in that order with the cells' parts of the segment. Triangle 0, in B and
// C, is hit at t = 3 (in C's part): when B finds it, the walk must go on to
// C, where triangle 1 is hit nearer, at t = 2.8.
struct PendingPartCopy {
  uint32_t node;
  float tmin, tmax;
};

TEST(KdTree, TheWalkVisitsCellsInOrderAndASpanningTriangleDoesNotEndItEarly) {
  // A triangle in the plane x = c around y = c - 0.5, where the ray meets
  // it at t = c + 2; wall(1) reaches below y = 0 (into B).
  const auto wall = [](float x) {
    const float y = x - 0.5f;
    return Triangle{{x, y - 1.0f, -1.0f}, {x, y - 1.0f, 1.0f}, {x, y + 1.0f, 0.0f}};
  };
  KdTree tree;
  tree.triangles = {wall(1.0f), wall(0.8f)};
  tree.records = {{tree.triangles[0].unit_normal(), 0, 0}, {tree.triangles[1].unit_normal(), 0, 1}};
  tree.bounds = {{-4, -4, -4}, {4, 4, 4}};
  tree.refs = {0, 0, 1};
  tree.nodes = {KdNode::inner(0, 0.0f, 2), KdNode::leaf(0, 0), KdNode::inner(1, 0.0f, 4), KdNode::leaf(0, 1),
                KdNode::leaf(1, 2)};
  ASSERT_TRUE(tree.view().validate().ok());

  Ray ray;
  ray.origin = {-2.0f, -2.5f, 0.0f};
  ray.direction = {1.0f, 1.0f, 0.0f};
  struct Visit {
    uint32_t first, count;
  };
  std::vector<Visit> visits;
  float limit = ray.tfar;
  kd_detail::traverse(tree.view(), ray, 0.0f, limit, [&](uint32_t first, uint32_t count, float&) {
    visits.push_back({first, count});
    return false;
  });
  ASSERT_EQ(visits.size(), 3u);
  EXPECT_EQ(visits[0].count, 0u);  // A
  EXPECT_EQ(visits[1].first, 0u);  // B
  EXPECT_EQ(visits[2].first, 1u);  // C

  Hit hit;
  ASSERT_TRUE(kd_closest_hit<WatertightTriangleTest>(tree.view(), ray, hit));
  EXPECT_EQ(hit.primitive_id, 1u);
  EXPECT_NEAR(hit.t, 2.8f, 1e-5f);

  // The same walk step by step, as the classic worked example: every node
  // entered, its part of the segment and the stack at that moment. The ray
  // meets x = 0 at t = 2 and y = 0 at t = 2.5; the bounds end at t = 6.
  struct Step {
    uint32_t node;
    float t0, t1;
    std::vector<PendingPartCopy> stack;
  };
  struct Recorder {
    std::vector<Step>* steps;
    void enter(uint32_t node, float t0, float t1, std::span<const kd_detail::PendingPart> stack) const {
      std::vector<PendingPartCopy> copy;
      for (const auto& p : stack) copy.push_back({p.node, p.tmin, p.tmax});
      steps->push_back({node, t0, t1, copy});
    }
  };
  std::vector<Step> steps;
  float best = ray.tfar;
  std::vector<uint32_t> leaves_hit;
  kd_detail::traverse(
      tree.view(), ray, 0.0f, best,
      [&](uint32_t first, uint32_t count, float& limit) {
        // The closest-hit leaf rule by hand: the nearest hit in the leaf
        // lowers the limit, and later parts beyond it are dropped.
        for (uint32_t k = first; k < first + count; ++k) {
          const float x = tree.triangles[tree.refs[k]].v0.x;
          limit = std::min(limit, x + 2.0f);  // the wall at x is met at t = x + 2
          leaves_hit.push_back(tree.refs[k]);
        }
        return false;
      },
      Recorder{&steps});
  ASSERT_EQ(steps.size(), 5u);
  const auto near = [](float a, float b) { return std::fabs(a - b) < 1e-4f; };
  // 1. The root with the whole segment and an empty stack; the plane x = 0
  //    is crossed inside it: the far child (2) waits with [2, 6].
  EXPECT_EQ(steps[0].node, 0u);
  EXPECT_TRUE(near(steps[0].t0, 0.0f) && near(steps[0].t1, 6.0f)) << steps[0].t0 << " " << steps[0].t1;
  EXPECT_TRUE(steps[0].stack.empty());
  // 2. Leaf A with [0, 2]; the stack holds node 2 with [2, 6].
  EXPECT_EQ(steps[1].node, 1u);
  EXPECT_TRUE(near(steps[1].t1, 2.0f));
  ASSERT_EQ(steps[1].stack.size(), 1u);
  EXPECT_EQ(steps[1].stack[0].node, 2u);
  EXPECT_TRUE(near(steps[1].stack[0].tmin, 2.0f) && near(steps[1].stack[0].tmax, 6.0f));
  // 3. A had nothing: node 2 is popped with [2, 6]; the stack is empty.
  EXPECT_EQ(steps[2].node, 2u);
  EXPECT_TRUE(near(steps[2].t0, 2.0f) && near(steps[2].t1, 6.0f));
  EXPECT_TRUE(steps[2].stack.empty());
  // 4. Leaf B with [2, 2.5]; leaf C waits with [2.5, 6]. B's triangle is hit
  //    at t = 3, beyond B's part: the walk must go on.
  EXPECT_EQ(steps[3].node, 3u);
  EXPECT_TRUE(near(steps[3].t0, 2.0f) && near(steps[3].t1, 2.5f));
  ASSERT_EQ(steps[3].stack.size(), 1u);
  EXPECT_EQ(steps[3].stack[0].node, 4u);
  EXPECT_TRUE(near(steps[3].stack[0].tmin, 2.5f));
  // 5. C (its part starts at 2.5 <= 3) with [2.5, 6] and an empty stack,
  //    where the nearer wall (t = 2.8) is found; then the stack is empty.
  EXPECT_EQ(steps[4].node, 4u);
  EXPECT_TRUE(near(steps[4].t0, 2.5f) && near(steps[4].t1, 6.0f));
  EXPECT_TRUE(steps[4].stack.empty());
  EXPECT_EQ(leaves_hit, (std::vector<uint32_t>{0, 0, 1}));
  EXPECT_TRUE(near(best, 2.8f));
}

TEST(KdTree, TheBuildReferencesEveryTriangleAndKeepsItsBudgets) {
  const BrickData bunny = load_brick_from(accel_test::bunny_path());
  const KdTreeBuilder::Result built = KdTreeBuilder::build(bunny.triangles, bunny.ids, {});
  const KdTree& tree = built.tree;
  ASSERT_TRUE(tree.view().validate().ok());
  std::vector<uint8_t> seen(tree.triangles.size(), 0);
  for (const uint32_t ref : tree.refs) seen[ref] = 1;
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 0), 0);
  const uint64_t n = bunny.triangles.size();
  EXPECT_LE(tree.refs.size(), KdTreeBuilder::kMaxReferencesPerTriangle * n + 64);
  EXPECT_LE(tree.memory_bytes(), KdTreeBuilder::tree_bytes_bound(n));
  EXPECT_LE(built.peak_bytes, KdTreeBuilder::peak_bytes_bound(n));
  EXPECT_GT(tree.nodes.size(), n / 8);  // it did split
  // A depth limit of 1 leaves one leaf with everything.
  KdTreeBuilder::Config shallow;
  shallow.max_depth = 1;
  const KdTree flat = KdTreeBuilder::build(bunny.triangles, bunny.ids, shallow).tree;
  ASSERT_EQ(flat.nodes.size(), 1u);
  EXPECT_EQ(flat.refs.size(), n);
}

TEST(KdTree, AViewThatDoesNotHoldTogetherIsAnError) {
  KdTree tree;
  tree.triangles = {Triangle{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
  tree.records = {{{0, 0, 1}, 0, 0}};
  tree.refs = {0};
  tree.nodes = {KdNode::inner(0, 0.5f, 1), KdNode::leaf(0, 1)};  // above child == below child
  EXPECT_FALSE(tree.view().validate().ok());
  tree.nodes = {KdNode::inner(0, 0.5f, 2), KdNode::leaf(0, 1), KdNode::leaf(0, 2)};  // past the refs
  EXPECT_FALSE(tree.view().validate().ok());
  tree.nodes = {KdNode::leaf(0, 1)};
  tree.refs = {7};  // no such triangle
  EXPECT_FALSE(tree.view().validate().ok());
}

TEST(KdTree, TheFactoryMakesItByNameAndRejectsBadOptions) {
  const BrickData sphere = load_brick_from("gen:sphere?level=3");
  split_tree_test::expect_the_factory_makes("kdtree", {{"triangle_test", "double"}, {"empty_bonus", "0.2"}},
                                            {{{"triangle_test", "exact"}},
                                             {{"empty_bonus", "1"}},
                                             {{"max_depth", "65"}},
                                             {{"intersection_cost", "-1"}},
                                             {{"bins", "8"}}},
                                            sphere, build_tree(sphere), 50);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
