#include "core/stress/stress_runner.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <tuple>

#include "core/accel/bvh/double_triangle_test.h"
#include "core/query/query_engine.h"

namespace outcore {
namespace {

std::string joined_names() {
  std::string out;
  for (const auto& c : stress_configs()) out += (out.empty() ? "" : ", ") + c.name;
  return out;
}

std::vector<uint32_t> all_ids(std::size_t n) {
  std::vector<uint32_t> ids(n);
  for (uint32_t i = 0; i < n; ++i) ids[i] = i;
  return ids;
}

Expected<std::vector<Hit>> trace_engine(const std::string& store, const StressConfig& config,
                                        const std::vector<Ray>& rays) {
  EngineOptions options;
  options.brick_accel = config.accel;
  options.accel_options = config.options;
  OUTCORE_ASSIGN_OR_RETURN(auto engine, QueryEngine::open(store, options));
  std::vector<Hit> hits(rays.size());
  OUTCORE_RETURN_IF_ERROR(engine->intersect(rays, hits, {}));
  return hits;
}

}  // namespace

const std::vector<StressConfig>& stress_configs() {
  static const std::vector<StressConfig> kConfigs = {
      {"embree", "embree", {{"robust", "0"}}, false},
      {"embree-robust", "embree", {{"robust", "1"}}, false},
      {"bvh-mt", "bvh", {{"triangle_test", "mt"}}, false},
      {"bvh-watertight", "bvh", {{"triangle_test", "watertight"}}, true},
      {"bvh-double", "bvh", {{"triangle_test", "double"}}, true},
      {"kdtree-watertight", "kdtree", {{"triangle_test", "watertight"}}, true},
      {"kdtree-double", "kdtree", {{"triangle_test", "double"}}, true},
      {"bsp-watertight", "bsp", {{"triangle_test", "watertight"}}, true},
      {"bsp-double", "bsp", {{"triangle_test", "double"}}, true},
      {"grid-watertight", "grid", {{"triangle_test", "watertight"}}, true},
      {"grid-double", "grid", {{"triangle_test", "double"}}, true},
      {"hgrid-watertight", "hgrid", {{"triangle_test", "watertight"}}, true},
      {"hgrid-double", "hgrid", {{"triangle_test", "double"}}, true},
      {"octree-watertight", "octree", {{"triangle_test", "watertight"}}, true},
      {"octree-double", "octree", {{"triangle_test", "double"}}, true},
      {"quadtree-watertight", "quadtree", {{"triangle_test", "watertight"}}, true},
      {"quadtree-double", "quadtree", {{"triangle_test", "double"}}, true},
  };
  return kConfigs;
}

Expected<std::vector<StressConfig>> select_stress_configs(const std::string& which) {
  if (which == "all") return stress_configs();
  for (const auto& c : stress_configs()) {
    if (c.name == which) return std::vector<StressConfig>{c};
  }
  return invalid_argument("unknown stress configuration '" + which + "' (known: all, " + joined_names() +
                          ")");
}

StressReference compute_stress_reference(const StressScene& scene, uint32_t max_checked) {
  StressReference ref;
  const std::size_t n = scene.rays.size();
  const std::size_t step =
      std::max<std::size_t>(1, (n + max_checked - 1) / std::max<uint32_t>(1, max_checked));
  for (std::size_t i = 0; i < n; i += step) {
    const Ray& ray = scene.rays[i];
    const auto prepared = DoubleTriangleTest::prepare(ray);
    double best = std::numeric_limits<double>::infinity();
    TriangleId best_id{kInvalidId, kInvalidId};
    for (std::size_t k = 0; k < scene.triangles.size(); ++k) {
      const Triangle& tri = scene.triangles[k];
      if (!tri.is_finite() || tri.is_degenerate()) continue;
      double t, u, v;
      if (!DoubleTriangleTest::hit_double(prepared, tri, ray.tnear, std::min<double>(ray.tfar, best), t, u,
                                          v)) {
        continue;
      }
      const TriangleId id = scene.ids[k];
      if (t < best || (t == best && std::tie(id.geometry_id, id.primitive_id) <
                                        std::tie(best_id.geometry_id, best_id.primitive_id))) {
        best = t;
        best_id = id;
      }
    }
    ref.checked.push_back(static_cast<uint32_t>(i));
    ref.t.push_back(best);
    ref.id.push_back(best_id);
  }
  return ref;
}

Expected<StressRow> run_stress(const StressScene& scene, const StressReference& reference,
                               const StressConfig& config) {
  StressRow row;
  row.scene = scene.name;
  row.family = scene.family;
  row.config = config.name;
  row.rays = scene.rays.size();
  std::vector<Hit> hits;
  if (scene.family == "seam") {
    OUTCORE_ASSIGN_OR_RETURN(hits, trace_engine(scene.tiny_bricks_store, config, scene.rays));
    OUTCORE_ASSIGN_OR_RETURN(auto one, trace_engine(scene.one_brick_store, config, scene.rays));
    row.seam_diffs = 0;
    for (std::size_t i = 0; i < hits.size(); ++i) {
      if (std::memcmp(&hits[i], &one[i], sizeof(Hit)) != 0) ++row.seam_diffs;
    }
  } else {
    OUTCORE_ASSIGN_OR_RETURN(auto builder, make_brick_builder(config.accel, config.options));
    BrickData brick;
    brick.triangles = scene.triangles;
    brick.ids = scene.ids;
    OUTCORE_ASSIGN_OR_RETURN(auto accel, builder->build(std::move(brick)));
    hits.assign(scene.rays.size(), Hit{});
    const auto ids = all_ids(scene.rays.size());
    accel->intersect(ids, scene.rays.data(), hits.data());
  }
  for (std::size_t i = 0; i < hits.size(); ++i) {
    if (scene.expect[i] == StressExpect::kHit && !hits[i].is_hit()) ++row.leaks;
    if (scene.expect[i] == StressExpect::kMiss && hits[i].is_hit()) ++row.wrong_hits;
  }
  row.checked = reference.checked.size();
  for (std::size_t c = 0; c < reference.checked.size(); ++c) {
    if (scene.expect[reference.checked[c]] == StressExpect::kMiss) continue;  // counted above
    const Hit& h = hits[reference.checked[c]];
    const double ref_t = reference.t[c];
    const bool ref_hit = ref_t != std::numeric_limits<double>::infinity();
    if (h.is_hit() != ref_hit) {
      ++row.wrong_hits;
      continue;
    }
    if (!ref_hit) continue;
    const double rel = std::fabs(double{h.t} - ref_t) / std::max(ref_t, std::numeric_limits<double>::min());
    row.max_rel_t_error = std::max(row.max_rel_t_error, rel);
    const bool same =
        h.geometry_id == reference.id[c].geometry_id && h.primitive_id == reference.id[c].primitive_id;
    if (!same && rel > kTieTolerance) ++row.wrong_hits;
  }
  return row;
}

std::string format_stress_table(const std::vector<StressRow>& rows) {
  std::string out;
  char line[256];
  std::snprintf(line, sizeof(line), "%-28s %-15s %8s %7s %8s %7s %12s %10s\n", "case", "config", "rays",
                "leaks", "checked", "wrong", "max rel t", "seam diffs");
  out += line;
  for (const StressRow& r : rows) {
    const std::string seam = r.seam_diffs < 0 ? "-" : std::to_string(r.seam_diffs);
    std::snprintf(line, sizeof(line), "%-28s %-15s %8llu %7llu %8llu %7llu %12.3g %10s\n", r.scene.c_str(),
                  r.config.c_str(), static_cast<unsigned long long>(r.rays),
                  static_cast<unsigned long long>(r.leaks), static_cast<unsigned long long>(r.checked),
                  static_cast<unsigned long long>(r.wrong_hits), r.max_rel_t_error, seam.c_str());
    out += line;
  }
  return out;
}

}  // namespace outcore
