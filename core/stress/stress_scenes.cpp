#include "core/stress/stress_scenes.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <tuple>
#include <utility>

#include "core/accel/bvh/double_triangle_test.h"
#include "core/source/source_factory.h"
#include "core/store/scene_packer.h"

namespace outcore {
namespace {

namespace fs = std::filesystem;

std::vector<TriangleId> sequential_ids(std::size_t n) {
  std::vector<TriangleId> ids(n);
  for (uint32_t k = 0; k < n; ++k) ids[k] = {0, k};
  return ids;
}

// Bit pattern of a vertex: exact equality, a total order for sorting.
using VertexKey = std::tuple<uint32_t, uint32_t, uint32_t>;
VertexKey key_of(const Vec3f& v) {
  uint32_t x, y, z;
  std::memcpy(&x, &v.x, 4);
  std::memcpy(&y, &v.y, 4);
  std::memcpy(&z, &v.z, 4);
  return {x, y, z};
}

// Distinct vertices and distinct edges (as vertex pairs) of a soup.
void vertices_and_edges(const std::vector<Triangle>& tris, std::vector<Vec3f>& vertices,
                        std::vector<std::pair<Vec3f, Vec3f>>& edges) {
  std::vector<std::pair<VertexKey, Vec3f>> vs;
  std::vector<std::tuple<VertexKey, VertexKey, Vec3f, Vec3f>> es;
  for (const Triangle& t : tris) {
    const Vec3f c[3] = {t.v0, t.v1, t.v2};
    for (int i = 0; i < 3; ++i) {
      vs.emplace_back(key_of(c[i]), c[i]);
      Vec3f a = c[i], b = c[(i + 1) % 3];
      if (key_of(b) < key_of(a)) std::swap(a, b);
      if (key_of(a) != key_of(b)) es.emplace_back(key_of(a), key_of(b), a, b);
    }
  }
  std::sort(vs.begin(), vs.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  vs.erase(std::unique(vs.begin(), vs.end(), [](const auto& x, const auto& y) { return x.first == y.first; }),
           vs.end());
  auto edge_less = [](const auto& x, const auto& y) {
    return std::tie(std::get<0>(x), std::get<1>(x)) < std::tie(std::get<0>(y), std::get<1>(y));
  };
  auto edge_equal = [](const auto& x, const auto& y) {
    return std::get<0>(x) == std::get<0>(y) && std::get<1>(x) == std::get<1>(y);
  };
  std::sort(es.begin(), es.end(), edge_less);
  es.erase(std::unique(es.begin(), es.end(), edge_equal), es.end());
  vertices.clear();
  for (const auto& v : vs) vertices.push_back(v.second);
  edges.clear();
  for (const auto& e : es) edges.emplace_back(std::get<2>(e), std::get<3>(e));
}

// Rays from `origin` aimed exactly at every stride-th vertex and edge
// midpoint (direction computed in float: the ray traced is this float ray).
void add_aimed_rays(StressScene& scene, const Vec3f& origin, uint32_t stride) {
  std::vector<Vec3f> vertices;
  std::vector<std::pair<Vec3f, Vec3f>> edges;
  vertices_and_edges(scene.triangles, vertices, edges);
  auto add = [&](const Vec3f& target) {
    Ray ray;
    ray.origin = origin;
    ray.direction = target - origin;
    if (ray.direction == Vec3f(0, 0, 0)) return;
    scene.rays.push_back(ray);
    scene.expect.push_back(StressExpect::kHit);
  };
  for (std::size_t i = 0; i < vertices.size(); i += stride) add(vertices[i]);
  for (std::size_t i = 0; i < edges.size(); i += stride) add((edges[i].first + edges[i].second) * 0.5f);
}

// Edges (between distinct vertices, of triangles that are not degenerate in
// float64) used an odd number of times: 0 for a closed mesh. Rounding a mesh
// far from the origin can make triangles degenerate (collapsed or collinear
// vertices), which opens holes that are the mesh's, not the tracer's.
std::size_t open_edges(const std::vector<Triangle>& tris) {
  std::vector<std::pair<VertexKey, VertexKey>> edges;
  for (const Triangle& t : tris) {
    if (t.is_degenerate()) continue;
    const Vec3f c[3] = {t.v0, t.v1, t.v2};
    for (int i = 0; i < 3; ++i) {
      VertexKey a = key_of(c[i]), b = key_of(c[(i + 1) % 3]);
      if (b < a) std::swap(a, b);
      edges.emplace_back(a, b);
    }
  }
  std::sort(edges.begin(), edges.end());
  std::size_t open = 0;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    open += (j - i) % 2;
    i = j;
  }
  return open;
}

// Crossings of the ray (origin p, direction d) with the mesh, float64 watertight.
int crossings(const std::vector<Triangle>& tris, const Vec3f& p, const Vec3f& d) {
  Ray ray;
  ray.origin = p;
  ray.direction = d;
  const auto prepared = DoubleTriangleTest::prepare(ray);
  int count = 0;
  for (const Triangle& tri : tris) {
    if (tri.is_degenerate()) continue;
    double t, u, v;
    if (DoubleTriangleTest::hit_double(prepared, tri, 0.0, std::numeric_limits<double>::infinity(), t, u,
                                       v)) {
      ++count;
    }
  }
  return count;
}

Aabb bounds_of(const std::vector<Triangle>& tris) {
  Aabb b;
  for (const Triangle& t : tris) b.extend(t.bounds());
  return b;
}

// The grid point (7^3 inside the bounds) nearest the bounds' centre that is
// inside by parity, or nullopt.
std::optional<Vec3f> find_interior_point(const std::vector<Triangle>& tris) {
  const Aabb b = bounds_of(tris);
  const Vec3d lo(b.lo), hi(b.hi), centre = (lo + hi) * 0.5;
  std::vector<Vec3d> candidates{centre};
  for (int i = 1; i < 8; ++i) {
    for (int j = 1; j < 8; ++j) {
      for (int k = 1; k < 8; ++k) {
        candidates.push_back(
            {lo.x + (hi.x - lo.x) * i / 8, lo.y + (hi.y - lo.y) * j / 8, lo.z + (hi.z - lo.z) * k / 8});
      }
    }
  }
  std::stable_sort(candidates.begin(), candidates.end(), [&](const Vec3d& x, const Vec3d& y) {
    return dot(x - centre, x - centre) < dot(y - centre, y - centre);
  });
  for (const Vec3d& c : candidates) {
    if (inside_by_parity(tris, Vec3f(c))) return Vec3f(c);
  }
  return std::nullopt;
}

struct Variant {
  std::string label;
  double scale;
  double offset;
};

const std::vector<Variant>& variants() {
  static const std::vector<Variant> kVariants = {
      {"", 1.0, 0.0},      {" +1e3", 1.0, 1e3},   {" +1e5", 1.0, 1e5},
      {" +1e6", 1.0, 1e6}, {" x1e-4", 1e-4, 0.0}, {" x1e6", 1e6, 0.0},
  };
  return kVariants;
}

Vec3f transformed(const Vec3f& p, const Variant& v) {
  return Vec3f(Vec3d(p) * v.scale + Vec3d(v.offset, v.offset, v.offset));
}

// Centred on the origin, largest half extent 1 (double, rounded once).
std::vector<Triangle> normalised(std::vector<Triangle> tris) {
  const Aabb b = bounds_of(tris);
  const Vec3d centre = (Vec3d(b.lo) + Vec3d(b.hi)) * 0.5;
  const Vec3d e = Vec3d(b.hi) - Vec3d(b.lo);
  const double s = 2.0 / std::max({e.x, e.y, e.z});
  auto f = [&](const Vec3f& p) { return Vec3f((Vec3d(p) - centre) * s); };
  for (Triangle& t : tris) t = {f(t.v0), f(t.v1), f(t.v2)};
  return tris;
}

// The closed-mesh scenes of one mesh: every variant, with its interior point.
void add_closed_mesh(StressScenes& out, const std::string& name, const std::vector<Triangle>& base,
                     std::optional<Vec3f> interior, uint32_t stride) {
  if (!interior) interior = find_interior_point(base);
  if (!interior) {
    out.notes.push_back(name + ": no interior point found by parity; skipped");
    return;
  }
  for (const Variant& v : variants()) {
    StressScene scene;
    scene.name = name + v.label;
    scene.family = "closed";
    scene.triangles.reserve(base.size());
    for (const Triangle& t : base) {
      scene.triangles.push_back({transformed(t.v0, v), transformed(t.v1, v), transformed(t.v2, v)});
    }
    scene.ids = sequential_ids(base.size());
    Vec3f origin = transformed(*interior, v);
    if (!inside_by_parity(scene.triangles, origin)) {
      const auto again = find_interior_point(scene.triangles);
      if (!again) {
        out.notes.push_back(scene.name + ": the rounded mesh has no interior point by parity; skipped");
        continue;
      }
      out.notes.push_back(scene.name + ": interior point moved (the transformed one was not inside)");
      origin = *again;
    }
    add_aimed_rays(scene, origin, stride);
    const std::size_t open = open_edges(scene.triangles);
    if (open > 0) {
      out.notes.push_back(scene.name + ": rounding to float left " + std::to_string(open) +
                          " open edges (degenerate triangles): misses are holes in the mesh, judged by the "
                          "reference only");
      std::fill(scene.expect.begin(), scene.expect.end(), StressExpect::kReference);
    }
    out.scenes.push_back(std::move(scene));
  }
}

// n x n unit squares in z = 0 (two triangles each, diagonals alternating),
// translated by (offset, offset, 0).
std::vector<Triangle> grid(int n, float offset) {
  std::vector<Triangle> tris;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const Vec3f a(offset + static_cast<float>(i), offset + static_cast<float>(j), 0);
      const Vec3f b = a + Vec3f(1, 0, 0), c = a + Vec3f(1, 1, 0), d = a + Vec3f(0, 1, 0);
      if ((i + j) % 2 == 0) {
        tris.push_back({a, b, c});
        tris.push_back({a, c, d});
      } else {
        tris.push_back({a, b, d});
        tris.push_back({b, c, d});
      }
    }
  }
  return tris;
}

// Bipyramid: n equator vertices on the unit circle, apexes at +-height.
// Zero-area triangles (a repeated vertex) are added along the equator.
std::vector<Triangle> bipyramid(int n, float height) {
  std::vector<Triangle> tris;
  const Vec3f top(0, 0, height), bottom(0, 0, -height);
  auto equator = [&](int i) {
    const double a = 2.0 * M_PI * (i % n) / n;
    return Vec3f(static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a)), 0.0f);
  };
  for (int i = 0; i < n; ++i) {
    const Vec3f a = equator(i), b = equator(i + 1);
    tris.push_back({a, b, top});
    tris.push_back({b, a, bottom});
    if (i % 4 == 0) {
      tris.push_back({a, a, b});
      tris.push_back({a, b, b});
    }
  }
  return tris;
}

Ray make_ray(const Vec3f& o, const Vec3f& d, float tnear = 0.0f,
             float tfar = std::numeric_limits<float>::infinity()) {
  Ray r;
  r.origin = o;
  r.direction = d;
  r.tnear = tnear;
  r.tfar = tfar;
  return r;
}

void add_axis_scenes(StressScenes& out, const std::vector<Triangle>& sphere) {
  StressScene s;
  s.name = "sphere axis-parallel";
  s.family = "axis";
  s.triangles = sphere;
  s.ids = sequential_ids(sphere.size());
  for (const float x : {0.0f, -0.0f, 0.25f, -0.5f}) {
    for (const float y : {0.0f, 0.125f, -0.375f}) {
      for (const float z : {0.0f, -0.0f, 0.5f}) {
        for (int axis = 0; axis < 3; ++axis) {
          for (const float sign : {1.0f, -1.0f}) {
            for (int zeros = 0; zeros < 4; ++zeros) {
              Vec3f d((zeros & 1) ? -0.0f : 0.0f, (zeros & 2) ? -0.0f : 0.0f, 0.0f);
              Vec3f dir;
              dir[axis] = sign;
              dir[(axis + 1) % 3] = d.x;
              dir[(axis + 2) % 3] = d.y;
              s.rays.push_back(make_ray({x, y, z}, dir));
              s.expect.push_back(StressExpect::kHit);
            }
          }
        }
      }
    }
  }
  out.scenes.push_back(std::move(s));

  for (const float offset : {0.0f, 1e6f}) {
    StressScene g;
    g.name = offset == 0.0f ? "grid axis-parallel" : "grid axis-parallel +1e6";
    g.family = "axis";
    g.triangles = grid(16, offset);
    g.ids = sequential_ids(g.triangles.size());
    for (int i = 0; i <= 32; ++i) {
      for (int j = 0; j <= 32; ++j) {
        const Vec3f o(offset + 0.5f * static_cast<float>(i), offset + 0.5f * static_cast<float>(j), 1.0f);
        for (int zeros = 0; zeros < 4; ++zeros) {
          g.rays.push_back(make_ray(o, {(zeros & 1) ? -0.0f : 0.0f, (zeros & 2) ? -0.0f : 0.0f, -1.0f}));
          g.expect.push_back(StressExpect::kHit);
        }
      }
    }
    out.scenes.push_back(std::move(g));
  }
}

void add_grazing_scenes(StressScenes& out, const std::vector<Triangle>& sphere) {
  for (const bool flat : {false, true}) {
    StressScene s;
    s.name = flat ? "grid grazing" : "sphere grazing";
    s.family = "grazing";
    s.triangles = flat ? grid(8, 0.0f) : sphere;
    s.ids = sequential_ids(s.triangles.size());
    for (const Triangle& t : s.triangles) {
      const Vec3f e = t.v1 - t.v0;
      const Vec3f c = t.centroid();
      s.rays.push_back(make_ray(c - e * 2.0f, e));      // through the face, in its plane
      s.rays.push_back(make_ray(t.v0 - e, e));          // along an edge
      s.rays.push_back(make_ray(t.v2 + e * 0.5f, -e));  // in the plane, parallel to an edge
      for (int k = 0; k < 3; ++k) s.expect.push_back(StressExpect::kReference);
    }
    out.scenes.push_back(std::move(s));
  }
}

void add_sliver_scenes(StressScenes& out, uint32_t stride) {
  for (const float height : {1.0f, 1e-3f}) {
    StressScene s;
    s.name = height == 1.0f ? "sliver bipyramid" : "flat sliver bipyramid";
    s.family = "sliver";
    s.triangles = bipyramid(1000, height);
    s.ids = sequential_ids(s.triangles.size());
    add_aimed_rays(s, Vec3f(0, 0, 0), stride);
    add_aimed_rays(s, Vec3f(0.01f, -0.02f, 0.3f * height), stride);
    out.scenes.push_back(std::move(s));
  }
}

void add_segment_scene(StressScenes& out) {
  StressScene s;
  s.name = "grid tnear/tfar at hit";
  s.family = "segment";
  s.triangles = grid(8, 0.0f);
  s.ids = sequential_ids(s.triangles.size());
  for (int i = 0; i < 16; ++i) {
    for (int j = 0; j < 16; ++j) {
      const Vec3f o(0.25f + 0.5f * static_cast<float>(i), 0.25f + 0.5f * static_cast<float>(j), 2.0f);
      for (const auto& [d, t] : {std::pair{Vec3f(0, 0, -1), 2.0f}, std::pair{Vec3f(0, 0, -0.5f), 4.0f}}) {
        const float tb = std::nextafter(t, 0.0f), ta = std::nextafter(t, 2 * t);
        s.rays.push_back(make_ray(o, d, 0.0f, t));  // tfar exactly at the hit: hit
        s.expect.push_back(StressExpect::kHit);
        s.rays.push_back(make_ray(o, d, tb, t));
        s.expect.push_back(StressExpect::kHit);
        s.rays.push_back(make_ray(o, d, t, ta));  // tnear exactly at the hit: miss
        s.expect.push_back(StressExpect::kMiss);
        s.rays.push_back(make_ray(o, d, 0.0f, tb));
        s.expect.push_back(StressExpect::kMiss);
      }
    }
  }
  out.scenes.push_back(std::move(s));
}

Status add_seam_scenes(StressScenes& out, bool quick, uint32_t stride) {
  OUTCORE_ASSIGN_OR_RETURN(auto workspace, StressWorkspace::create());
  const std::string level = quick ? "3" : "4";
  const std::vector<std::pair<std::string, std::string>> specs = {
      {"sphere seams", "gen:sphere?level=" + level},
      {"sphere seams +1e6", "gen:sphere?level=" + level + "&cx=1e6&cy=1e6&cz=1e6"},
      {"torus seams", "gen:torus?nu=48&nv=24"},
  };
  int index = 0;
  for (const auto& [name, spec] : specs) {
    StressScene s;
    s.name = name;
    s.family = "seam";
    OUTCORE_ASSIGN_OR_RETURN(s.triangles, read_all_triangles(spec));
    s.ids = sequential_ids(s.triangles.size());
    const bool torus = spec.find("torus") != std::string::npos;
    Vec3f origin;
    if (torus) {
      origin = Vec3f(1, 0, 0);  // on the core circle (major radius 1)
    } else {
      const Aabb b = bounds_of(s.triangles);
      origin = b.center();
    }
    if (!inside_by_parity(s.triangles, origin))
      return internal_error("stress: " + name + " origin not inside");
    add_aimed_rays(s, origin, stride);
    for (const uint32_t bricks : {16u, 1u << 24}) {
      PackOptions pack;
      pack.inputs = {spec};
      pack.output = (workspace->path() / ("scene" + std::to_string(index++))).string();
      pack.brick_triangles = bricks;
      pack.sync = false;
      OUTCORE_RETURN_IF_ERROR(pack_scene(pack).status());
      (bricks == 16 ? s.tiny_bricks_store : s.one_brick_store) = pack.output;
    }
    s.workspace = workspace;
    out.scenes.push_back(std::move(s));
  }
  return Status::Ok();
}

}  // namespace

Expected<std::shared_ptr<StressWorkspace>> StressWorkspace::create() {
  std::shared_ptr<StressWorkspace> workspace(new StressWorkspace());
  OUTCORE_RETURN_IF_ERROR(
      workspace->directory_.create((fs::path(default_temp_directory()) / "outcore-stress-").string()));
  return workspace;
}

bool inside_by_parity(const std::vector<Triangle>& triangles, const Vec3f& p) {
  static const Vec3f kDirections[] = {
      {0.5772f, 0.5774f, 0.5778f}, {-0.3137f, 0.8612f, -0.4001f}, {0.7071f, -0.1234f, -0.6961f}};
  for (const Vec3f& d : kDirections) {
    if (crossings(triangles, p, d) % 2 == 0) return false;
  }
  return true;
}

Expected<StressScenes> make_stress_scenes(const StressOptions& options) {
  StressScenes out;
  const uint32_t stride = std::max(1u, options.stride);
  OUTCORE_ASSIGN_OR_RETURN(auto sphere,
                           read_all_triangles(options.quick ? "gen:sphere?level=3" : "gen:sphere?level=4"));
  OUTCORE_ASSIGN_OR_RETURN(
      auto torus, read_all_triangles(options.quick ? "gen:torus?nu=48&nv=24" : "gen:torus?nu=96&nv=48"));
  // The icosphere is centred on the origin; the torus's core circle has radius
  // 1 (its default major radius) about the z axis.
  add_closed_mesh(out, "sphere", sphere, Vec3f(0, 0, 0), stride);
  add_closed_mesh(out, "torus", torus, Vec3f(1, 0, 0), stride);
  if (!options.models_dir.empty()) {
    for (const char* model : {"fandisk", "homer", "spot", "beast"}) {
      const fs::path path = fs::path(options.models_dir) / (std::string(model) + ".obj");
      if (!fs::exists(path)) {
        out.notes.push_back(std::string(model) + ": " + path.string() + " not found; skipped");
        continue;
      }
      OUTCORE_ASSIGN_OR_RETURN(auto tris, read_all_triangles(path.string()));
      add_closed_mesh(out, model, normalised(std::move(tris)), std::nullopt, stride);
    }
  }
  add_axis_scenes(out, sphere);
  add_grazing_scenes(out, sphere);
  add_sliver_scenes(out, stride);
  add_segment_scene(out);
  OUTCORE_RETURN_IF_ERROR(add_seam_scenes(out, options.quick, stride));
  return out;
}

}  // namespace outcore
