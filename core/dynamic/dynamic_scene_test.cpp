// Tests of the dynamic layer: refitted meshes and top levels answer exactly
// as fresh builds of the same version, and as float64 brute force over the
// world triangles (0 wrong hits); versions are atomic and kept; bad input is
// a named error that changes nothing; closed meshes moved and deformed do
// not leak; queries during a stream of updates each see one version.
#include "core/dynamic/dynamic_scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <set>
#include <thread>
#include <tuple>

#include "core/accel/brute_force_reference.h"
#include "core/gen/generator_factory.h"
#include "core/io/triangle_source.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

struct IndexedMesh {
  std::vector<float> vertices;
  std::vector<uint32_t> triangles;
};

// A generator's triangles with equal positions merged into shared vertices
// (the icosphere is closed and watertight by construction).
IndexedMesh indexed(const std::string& spec) {
  struct Collect final : TriangleSink {
    IndexedMesh mesh;
    std::map<std::tuple<float, float, float>, uint32_t> index;
    uint32_t vertex(const Vec3f& p) {
      const auto [it, added] = index.try_emplace({p.x, p.y, p.z}, static_cast<uint32_t>(index.size()));
      if (added) mesh.vertices.insert(mesh.vertices.end(), {p.x, p.y, p.z});
      return it->second;
    }
    Status consume(std::span<const Triangle> batch) override {
      for (const Triangle& t : batch)
        mesh.triangles.insert(mesh.triangles.end(), {vertex(t.v0), vertex(t.v1), vertex(t.v2)});
      return Status::Ok();
    }
  } sink;
  auto source = make_generator(spec);
  EXPECT_TRUE(source.ok());
  EXPECT_TRUE((*source)->stream(sink).ok());
  return sink.mesh;
}

// Row-major 3x4: rotation about z by `angle`, uniform `scale`, then `offset`.
std::vector<double> placement(double angle, double scale, Vec3d offset, double shear = 0) {
  const double c = std::cos(angle) * scale, s = std::sin(angle) * scale;
  return {c, -s, shear, offset.x, s, c, 0, offset.y, 0, 0, scale, offset.z};
}

// The world triangles and ids of a snapshot, in float64 placement rounded
// to float (what brute force is given).
struct WorldTriangles {
  std::vector<Triangle> triangles;
  std::vector<TriangleId> ids;
};
WorldTriangles world_triangles(const DynamicSnapshot& s) {
  WorldTriangles w;
  for (const DynamicInstance& instance : s.instances) {
    const DynamicMesh& mesh = *s.meshes[instance.mesh_id];
    const auto v = mesh.vertices();
    for (uint32_t t = 0; t < mesh.triangle_count(); ++t) {
      const auto& [a, b, c] = mesh.topology()->triangles[t];
      const auto place = [&](uint32_t k) { return Vec3f(instance.to_world.point(Vec3d(v[k]))); };
      w.triangles.push_back({place(a), place(b), place(c)});
      w.ids.push_back({instance.geometry_id, t});
    }
  }
  return w;
}

std::vector<Ray> rays_through(const Aabb& box, std::size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0, 1);
  const Vec3f e = box.extent();
  const auto inside = [&] {
    return Vec3f(box.lo.x + unit(rng) * e.x, box.lo.y + unit(rng) * e.y, box.lo.z + unit(rng) * e.z);
  };
  std::vector<Ray> rays(n);
  for (Ray& r : rays) {
    const Vec3f from = inside() + (inside() - box.center()) * 3.0f;
    r.origin = from;
    r.direction = inside() - from;
  }
  return rays;
}

std::vector<Hit> trace(const DynamicSnapshot& s, const std::vector<Ray>& rays) {
  std::vector<Hit> hits(rays.size());
  s.intersect(rays, hits);
  return hits;
}

// A fresh build of the same version: every mesh and the top level built anew.
DynamicSnapshot rebuilt(const DynamicSnapshot& s) {
  DynamicSnapshot fresh = s;
  for (auto& mesh : fresh.meshes) mesh = mesh->rebuilt_fresh();
  build_dynamic_top_level(fresh);
  return fresh;
}

void expect_bitwise(const std::vector<Hit>& a, const std::vector<Hit>& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)), 0) << what;
}

// Against float64 brute force: the same triangle, or (a tie or a graze)
// both at the same t within a relative 1e-5; hits and misses agree but for
// rays within that distance of an edge (counted, must be rare).
void expect_matches_reference(const DynamicSnapshot& s, const std::vector<Ray>& rays,
                              const std::vector<Hit>& hits, const std::string& what) {
  const WorldTriangles w = world_triangles(s);
  std::size_t hit_count = 0, grazes = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const ReferenceHit ref = reference_closest_hit(w.triangles, w.ids, rays[i]);
    hit_count += ref.is_hit();
    if (ref.is_hit() != hits[i].is_hit()) {
      ++grazes;
      continue;
    }
    if (!ref.is_hit()) continue;
    if (ref.geometry_id == hits[i].geometry_id && ref.primitive_id == hits[i].primitive_id) {
      EXPECT_NEAR(hits[i].t, ref.t, 1e-5 * std::max(1.0, ref.t)) << what << " ray " << i;
      EXPECT_NEAR(dot(Vec3d(hits[i].normal), ref.normal), 1.0, 1e-5) << what << " ray " << i;
    } else {
      EXPECT_NEAR(hits[i].t, ref.t, 1e-5 * std::max(1.0, ref.t))
          << what << " ray " << i << ": another triangle";
    }
  }
  EXPECT_GT(hit_count, rays.size() / 10) << what;
  EXPECT_LE(grazes, rays.size() / 1000 + 1) << what;
}

class DynamicSceneTest : public ::testing::Test {
 protected:
  IndexedMesh sphere_ = indexed("gen:sphere?level=3");  // 1280 triangles
  IndexedMesh torus_ = indexed("gen:torus?major=2&minor=0.5&nu=24&nv=12");
};

TEST_F(DynamicSceneTest, InstancesAnswerAsBruteForceOverTheirWorldTriangles) {
  DynamicScene scene(100);
  const auto sphere = scene.add_mesh(sphere_.vertices, sphere_.triangles);
  const auto torus = scene.add_mesh(torus_.vertices, torus_.triangles);
  ASSERT_TRUE(sphere.ok() && torus.ok()) << sphere.status().to_string() << torus.status().to_string();
  std::vector<uint32_t> ids;
  for (int k = 0; k < 12; ++k) {
    const auto id = scene.add_instance(
        k % 2 ? torus->id : sphere->id,
        placement(0.3 * k, 0.5 + 0.1 * k, {3.0 * (k % 4), 3.0 * (k / 4), 0.2 * k}, k == 5 ? 0.4 : 0.0));
    ASSERT_TRUE(id.ok()) << id.status().to_string();
    ids.push_back(id->id);
    EXPECT_EQ(id->version, scene.latest()->version);
  }
  EXPECT_EQ(ids.front(), 100u) << "dynamic ids continue after the static ones";
  EXPECT_EQ(ids.back(), 111u);
  const auto s = scene.latest();
  EXPECT_EQ(s->version, 14u);  // two meshes, twelve instances
  Aabb box;
  for (const auto& i : s->instances) box.extend(i.world_box);
  const std::vector<Ray> rays = rays_through(box, 3000, 1);
  const std::vector<Hit> hits = trace(*s, rays);
  expect_matches_reference(*s, rays, hits, "12 instances");
  // Any hit agrees with closest hit.
  std::vector<uint8_t> occluded(rays.size());
  s->occluded(rays, occluded);
  for (std::size_t i = 0; i < rays.size(); ++i) EXPECT_EQ(occluded[i] != 0, hits[i].is_hit()) << "ray " << i;
}

TEST_F(DynamicSceneTest, RefitsAnswerBitwiseAsFreshBuildsOfTheSameVersion) {
  DynamicScene scene;
  const uint32_t mesh = scene.add_mesh(torus_.vertices, torus_.triangles)->id;
  std::vector<uint32_t> ids;
  for (int k = 0; k < 40; ++k)
    ids.push_back(scene.add_instance(mesh, placement(0.1 * k, 1, {5.0 * (k % 8), 5.0 * (k / 8), 0}))->id);
  std::vector<float> moving = torus_.vertices;
  for (int frame = 1; frame <= 30; ++frame) {
    // A smooth wave through the mesh, and every instance drifting and turning.
    for (std::size_t v = 0; v < moving.size(); v += 3)
      moving[v + 2] = torus_.vertices[v + 2] + 0.3f * std::sin(0.2f * frame + torus_.vertices[v]);
    ASSERT_TRUE(scene.update_vertices(mesh, moving).ok());
    std::vector<double> transforms;
    for (int k = 0; k < 40; ++k) {
      const auto t =
          placement(0.1 * k + 0.05 * frame, 1, {5.0 * (k % 8) + 0.1 * frame, 5.0 * (k / 8), 0.05 * frame});
      transforms.insert(transforms.end(), t.begin(), t.end());
    }
    const auto version = scene.update_transforms(ids, transforms);
    ASSERT_TRUE(version.ok()) << version.status().to_string();
    if (frame % 10 != 0) continue;
    const auto s = scene.latest();
    EXPECT_EQ(s->version, *version);
    Aabb box;
    for (const auto& i : s->instances) box.extend(i.world_box);
    const std::vector<Ray> rays = rays_through(box, 2000, frame);
    const std::vector<Hit> hits = trace(*s, rays);
    expect_bitwise(hits, trace(rebuilt(*s), rays), "frame " + std::to_string(frame));
    expect_matches_reference(*s, rays, hits, "frame " + std::to_string(frame));
  }
  const DynamicScene::Counters c = scene.counters();
  EXPECT_EQ(c.mesh_rebuilds, 0u) << "smooth motion refits";
  EXPECT_EQ(c.mesh_refits, 30u);
  EXPECT_GT(c.top_refits, 0u);
}

TEST_F(DynamicSceneTest, TheBkdTopLevelAnswersAsTheBvhOneThroughUpdatesAndRebuilds) {
  DynamicScene bvh, bkd(0, DynamicTopLevel::kBkd);
  std::vector<uint32_t> ids;
  for (DynamicScene* scene : {&bvh, &bkd}) {
    const uint32_t mesh = scene->add_mesh(torus_.vertices, torus_.triangles)->id;
    ids.clear();
    for (int k = 0; k < 50; ++k)
      ids.push_back(
          scene->add_instance(mesh, placement(0.2 * k, 0.2, {3.0 * (k % 10), 3.0 * (k / 10), 0.1 * k}))->id);
  }
  EXPECT_FALSE(bkd.latest()->bkd.empty());
  EXPECT_TRUE(bkd.latest()->top.empty());
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> step(-0.5, 0.5);
  std::vector<Vec3d> at(50);
  for (int k = 0; k < 50; ++k) at[k] = {3.0 * (k % 10), 3.0 * (k / 10), 0.1 * k};
  for (int frame = 1; frame <= 40; ++frame) {
    // A random walk, then (frames 31-40) every instance somewhere else.
    std::vector<double> transforms;
    for (int k = 0; k < 50; ++k) {
      at[k] = frame > 30 ? Vec3d(step(rng), step(rng), step(rng)) * 60.0  // scrambled: anywhere
                         : at[k] + Vec3d(step(rng), step(rng), step(rng));
      const auto t = placement(0.2 * k + 0.1 * frame, 0.2, at[k]);
      transforms.insert(transforms.end(), t.begin(), t.end());
    }
    ASSERT_TRUE(bvh.update_transforms(ids, transforms).ok());
    ASSERT_TRUE(bkd.update_transforms(ids, transforms).ok());
    if (frame % 10 != 0) continue;
    Aabb box;
    for (const auto& i : bvh.latest()->instances) box.extend(i.world_box);
    std::vector<Ray> rays = rays_through(box, 1500, frame);
    for (std::size_t i = 0; i < rays.size(); i += 2)  // every other one aimed at an instance
      rays[i].direction = bvh.latest()->instances[i % 50].world_box.center() - rays[i].origin;
    const std::vector<Hit> hits = trace(*bkd.latest(), rays);
    EXPECT_GT(std::count_if(hits.begin(), hits.end(), [](const Hit& h) { return h.is_hit(); }), 100);
    expect_bitwise(hits, trace(*bvh.latest(), rays), "frame " + std::to_string(frame));
    expect_bitwise(hits, trace(rebuilt(*bkd.latest()), rays), "rebuilt, frame " + std::to_string(frame));
    std::vector<uint8_t> a(rays.size()), b(rays.size());
    bkd.latest()->occluded(rays, a);
    bvh.latest()->occluded(rays, b);
    EXPECT_EQ(a, b);
  }
  EXPECT_GT(bkd.counters().top_refits, 0u);
  EXPECT_GT(bkd.counters().top_rebuilds, 50u) << "scrambled by the last frames: rebuilt";
  EXPECT_GT(bvh.counters().top_rebuilds, 50u) << "scrambled by the last frames: rebuilt";
}

TEST_F(DynamicSceneTest, AScramblingMotionTriggersARebuild) {
  DynamicScene scene;
  const uint32_t mesh = scene.add_mesh(sphere_.vertices, sphere_.triangles)->id;
  ASSERT_TRUE(scene.add_instance(mesh, placement(0, 1, {0, 0, 0})).ok());
  std::vector<float> scrambled = sphere_.vertices;
  std::mt19937 rng(7);
  const std::size_t n = scrambled.size() / 3;
  for (std::size_t v = 0; v < n; ++v) {
    const std::size_t w = rng() % n;
    for (int a = 0; a < 3; ++a) std::swap(scrambled[3 * v + a], scrambled[3 * w + a]);
  }
  ASSERT_TRUE(scene.update_vertices(mesh, scrambled).ok());
  const auto s = scene.latest();
  EXPECT_TRUE(s->meshes[mesh]->rebuilt());
  EXPECT_LE(s->meshes[mesh]->sah_cost(), DynamicMesh::kRebuildRatio * s->meshes[mesh]->built_sah_cost());
  EXPECT_EQ(scene.counters().mesh_rebuilds, 1u);
  const std::vector<Ray> rays = rays_through(s->instances[0].world_box, 1500, 3);
  const std::vector<Hit> hits = trace(*s, rays);
  expect_bitwise(hits, trace(rebuilt(*s), rays), "scrambled");
  expect_matches_reference(*s, rays, hits, "scrambled");
}

TEST_F(DynamicSceneTest, ClosedMeshesMovedAndDeformedDoNotLeakAtVerticesAndEdges) {
  DynamicScene scene;
  const uint32_t mesh = scene.add_mesh(sphere_.vertices, sphere_.triangles)->id;
  const std::vector<Vec3d> centres = {{0, 0, 0}, {1e3, -2e3, 5e2}, {-7.5, 3.25, 1e4}, {1e6, -1e6, 3e5}};
  std::vector<uint32_t> ids;
  for (std::size_t k = 0; k < centres.size(); ++k)
    ids.push_back(scene.add_instance(mesh, placement(0.7 * k, 1.5, centres[k], 0.2))->id);
  std::vector<float> squashed = sphere_.vertices;
  for (std::size_t v = 0; v < squashed.size(); v += 3) squashed[v] *= 1.7f;
  ASSERT_TRUE(scene.update_vertices(mesh, squashed).ok());
  const auto s = scene.latest();
  // From inside each instance, and from outside towards its centre, rays
  // aimed exactly at every world vertex and edge midpoint of it: each must
  // hit that instance (no leak).
  std::size_t leaks = 0, rays_cast = 0;
  for (const DynamicInstance& instance : s->instances) {
    const auto v = s->meshes[mesh]->vertices();
    std::vector<Ray> rays;
    const Vec3f centre(instance.to_world.point({0.01, -0.02, 0.015}));
    for (const auto& tri : s->meshes[mesh]->topology()->triangles) {
      for (int k = 0; k < 3; ++k) {
        const Vec3d a(v[tri[k]]), b(v[tri[(k + 1) % 3]]);
        for (const Vec3d& target : {a, (a + b) * 0.5}) {
          const Vec3f world(instance.to_world.point(target));
          Ray r;
          r.origin = centre;
          r.direction = world - centre;
          rays.push_back(r);
          // And from outside, inward through the same point.
          r.origin = centre + (world - centre) * 8.0f;
          r.direction = centre - r.origin;
          rays.push_back(r);
        }
      }
    }
    const std::vector<Hit> hits = trace(*s, rays);
    for (const Hit& h : hits) leaks += !h.is_hit() || h.geometry_id != instance.geometry_id;
    rays_cast += rays.size();
  }
  EXPECT_EQ(leaks, 0u) << "of " << rays_cast;
}

TEST_F(DynamicSceneTest, AQueryHoldsItsVersionWhileUpdatesPublishNewOnes) {
  DynamicScene scene;
  const uint32_t mesh = scene.add_mesh(sphere_.vertices, sphere_.triangles)->id;
  const uint32_t id = scene.add_instance(mesh, placement(0, 1, {0, 0, 0}))->id;
  const auto before = scene.latest();
  const std::vector<Ray> rays = rays_through(before->instances[0].world_box, 500, 5);
  const std::vector<Hit> hits_before = trace(*before, rays);
  const double moved[12] = {1, 0, 0, 10, 0, 1, 0, 0, 0, 0, 1, 0};
  const auto v = scene.update_transforms({&id, 1}, moved);
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(*v, before->version + 1);
  expect_bitwise(trace(*before, rays), hits_before, "the old version is unchanged");
  const auto again = scene.at(before->version);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->get(), before.get());
  // The rays aimed at the old place now mostly miss the moved instance.
  std::size_t hits_now = 0, hits_then = 0;
  for (const Hit& h : trace(*scene.latest(), rays)) hits_now += h.is_hit();
  for (const Hit& h : hits_before) hits_then += h.is_hit();
  EXPECT_GT(hits_then, 100u);
  EXPECT_LT(hits_now, hits_then / 10);
  // Only the last kKeptVersions are kept; a future one does not exist.
  for (std::size_t k = 0; k < DynamicScene::kKeptVersions; ++k)
    ASSERT_TRUE(scene.update_transforms({&id, 1}, moved).ok());
  const auto gone = scene.at(before->version);
  ASSERT_FALSE(gone.ok());
  EXPECT_NE(gone.status().message().find("no longer kept"), std::string::npos) << gone.status().to_string();
  EXPECT_FALSE(scene.at(scene.latest()->version + 1).ok());
}

TEST_F(DynamicSceneTest, BadInputIsANamedErrorThatChangesNothing) {
  DynamicScene scene(7);
  const uint32_t mesh = scene.add_mesh(sphere_.vertices, sphere_.triangles)->id;
  const uint32_t id = scene.add_instance(mesh, placement(0, 1, {0, 0, 0}))->id;
  const auto before = scene.latest();
  const auto expect_error = [&](const Status& status, const std::string& words) {
    EXPECT_FALSE(status.ok()) << words;
    EXPECT_NE(status.message().find(words), std::string::npos) << status.to_string();
    EXPECT_EQ(scene.latest().get(), before.get()) << "nothing published after: " << status.to_string();
  };
  std::vector<double> nan_transform = placement(0, 1, {0, 0, 0});
  nan_transform[5] = std::nan("");
  const std::vector<double> singular = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0};
  expect_error(scene.update_transforms({&id, 1}, nan_transform).status(), "element [1][1] is not finite");
  expect_error(scene.update_transforms({&id, 1}, singular).status(), "singular");
  expect_error(scene.update_transforms({&id, 1}, std::vector<double>(11, 1.0)).status(), "12 each");
  const uint32_t unknown = 99;
  expect_error(scene.update_transforms({&unknown, 1}, placement(0, 1, {0, 0, 0})).status(), "geometry 99");
  const uint32_t twice[2] = {id, id};
  std::vector<double> two = placement(0, 1, {0, 0, 0});
  two.insert(two.end(), two.begin(), two.end());
  expect_error(scene.update_transforms(twice, two).status(), "appears twice");
  // A bad entry after a good one: all or nothing.
  const uint32_t good_then_bad[2] = {id, unknown};
  expect_error(scene.update_transforms(good_then_bad, two).status(), "entry 1");
  expect_error(scene.add_instance(5, placement(0, 1, {0, 0, 0})).status(), "no mesh 5");
  std::vector<float> fewer(sphere_.vertices.begin(), sphere_.vertices.end() - 3);
  expect_error(scene.update_vertices(mesh, fewer).status(), "topology is fixed");
  std::vector<float> nan_vertex = sphere_.vertices;
  nan_vertex[31] = std::nanf("");
  expect_error(scene.update_vertices(mesh, nan_vertex).status(), "vertex 10 is not finite");
  expect_error(scene.update_vertices(mesh, std::vector<float>(10, 0.0f)).status(), "not a multiple of 3");
  expect_error(scene.remove(unknown).status(), "geometry id 99");
  std::vector<uint32_t> bad_index = sphere_.triangles;
  bad_index[7] = 1u << 30;
  expect_error(scene.add_mesh(sphere_.vertices, bad_index).status(), "triangle 2 names vertex");
  expect_error(scene.add_mesh(sphere_.vertices, {}).status(), "no triangles");
  // And a good change still works after all of them.
  EXPECT_TRUE(scene.remove(id).ok());
  EXPECT_TRUE(scene.latest()->instances.empty());
}

TEST_F(DynamicSceneTest, QueriesDuringAStreamOfUpdatesEachMatchOneVersion) {
  DynamicScene scene;
  const uint32_t mesh = scene.add_mesh(torus_.vertices, torus_.triangles)->id;
  std::vector<uint32_t> ids;
  for (int k = 0; k < 16; ++k)
    ids.push_back(scene.add_instance(mesh, placement(0, 1, {4.0 * (k % 4), 4.0 * (k / 4), 0}))->id);
  const std::vector<Ray> rays = rays_through(scene.latest()->top.empty() ? Aabb{} : [&] {
    Aabb b;
    for (const auto& i : scene.latest()->instances) b.extend(i.world_box);
    return b;
  }(), 400, 9);
  std::atomic<bool> done{false};
  std::atomic<int> queries{0};
  std::thread writer([&] {
    for (int frame = 1; frame <= 60; ++frame) {
      // Interleaved with the reader: one update after each of its queries
      // (the next query then runs while the update is made).
      while (queries.load() < frame) std::this_thread::yield();
      std::vector<double> transforms;
      for (int k = 0; k < 16; ++k) {
        const auto t = placement(0.05 * frame * (k % 3), 1, {4.0 * (k % 4), 4.0 * (k / 4), 0.1 * frame});
        transforms.insert(transforms.end(), t.begin(), t.end());
      }
      EXPECT_TRUE(scene.update_transforms(ids, transforms).ok());
    }
    done = true;
  });
  struct Seen {
    std::shared_ptr<const DynamicSnapshot> snapshot;
    std::vector<Hit> hits;
  };
  std::vector<Seen> seen;
  while (!done || seen.size() < 3) {
    auto s = scene.latest();
    seen.push_back({s, trace(*s, rays)});
    ++queries;
  }
  writer.join();
  std::set<uint64_t> versions;
  for (const Seen& q : seen) versions.insert(q.snapshot->version);
  EXPECT_GE(versions.size(), 2u) << "queries saw the stream of versions";
  for (const Seen& q : seen)
    expect_bitwise(q.hits, trace(rebuilt(*q.snapshot), rays),
                   "version " + std::to_string(q.snapshot->version));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
