#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "core/accel/brick_accel_factory.h"
#include "core/cache/cache_budget.h"
#include "core/cli/commands.h"
#include "core/proxy/proxy_file.h"
#include "core/store/scene_store.h"
#include "core/util/json_writer.h"
#include "core/util/progress.h"

namespace outcore {

namespace {

struct BrickSizeStats {
  uint32_t min = 0, p10 = 0, median = 0, p90 = 0, max = 0;
  double mean = 0;
};

BrickSizeStats brick_size_stats(const Manifest& m) {
  std::vector<uint32_t> sizes;
  for (const auto& b : m.bricks) sizes.push_back(b.triangle_count);
  std::sort(sizes.begin(), sizes.end());
  BrickSizeStats s;
  auto at = [&](double q) {
    return sizes[std::min(sizes.size() - 1, static_cast<size_t>(q * (sizes.size() - 1) + 0.5))];
  };
  s.min = sizes.front();
  s.p10 = at(0.1);
  s.median = at(0.5);
  s.p90 = at(0.9);
  s.max = sizes.back();
  s.mean = static_cast<double>(m.triangle_count) / sizes.size();
  return s;
}

// What the store's proxies.bin (written by the engine on first open) holds.
struct ProxyInfo {
  std::string state;  // "absent", "valid", "stale" (another store) or "corrupt"
  ProxyFileHeader header{};
  uint64_t file_bytes = 0;
};

ProxyInfo proxy_info(const SceneStore& store) {
  ProxyInfo info;
  const std::string path = store.directory() + "/" + kProxyFileName;
  const auto header = read_proxy_file_header(path);
  if (!header.ok()) {
    info.state = header.status().code() == StatusCode::kNotFound ? "absent" : "corrupt";
    return info;
  }
  info.header = *header;
  info.file_bytes = sizeof(ProxyFileHeader) + header->payload_bytes;
  const bool ours = header->store_fingerprint == store_fingerprint(store.manifest()) &&
                    header->brick_count == store.brick_count();
  info.state = ours ? "valid" : "stale";
  return info;
}

// The smallest --cache-mb for `trace` and `serve`, per brick structure with
// its default options (the cache reserves each brick's build bound).
struct MinimumBudgetRow {
  std::string accel;
  MinimumCacheBudget minimum;
};

std::vector<MinimumBudgetRow> minimum_budgets(const Manifest& m) {
  std::vector<MinimumBudgetRow> rows;
  for (const char* accel : {"embree", "bvh"}) {
    auto builder = make_brick_builder(accel, {});
    if (builder.ok()) rows.push_back({accel, minimum_cache_budget(m, **builder)});
  }
  return rows;
}

void write_box(JsonWriter& j, const Aabb& b) {
  j.begin_object().key("min").begin_array().value(b.lo.x).value(b.lo.y).value(b.lo.z).end_array();
  j.key("max").begin_array().value(b.hi.x).value(b.hi.y).value(b.hi.z).end_array().end_object();
}

std::string info_json(const SceneStore& store) {
  const Manifest& m = store.manifest();
  const BrickSizeStats sizes = brick_size_stats(m);
  JsonWriter j;
  j.begin_object();
  j.field("store", store.directory());
  j.field("format_version", m.format_version);
  j.field("outcore_version", m.outcore_version);
  j.key("inputs").begin_array();
  for (size_t i = 0; i < m.inputs.size(); ++i) {
    j.begin_object().field("geometry_id", static_cast<uint64_t>(i)).field("spec", m.inputs[i].spec);
    j.field("triangles", m.inputs[i].triangle_count)
        .field("degenerate_triangles", m.inputs[i].degenerate_count);
    j.end_object();
  }
  j.end_array();
  j.field("triangles", m.triangle_count).field("degenerate_triangles", m.degenerate_count);
  j.key("bounds");
  write_box(j, m.bounds);
  j.field("bricks", static_cast<uint64_t>(m.bricks.size()))
      .field("brick_triangles_target", m.brick_triangles_target);
  j.key("brick_triangles").begin_object();
  j.field("min", sizes.min).field("p10", sizes.p10).field("median", sizes.median).field("p90", sizes.p90);
  j.field("max", sizes.max).field("mean", sizes.mean).end_object();
  j.key("upper_hierarchy").begin_object();
  j.field("nodes", static_cast<uint64_t>(m.upper.nodes.size())).field("depth", m.upper.depth()).end_object();
  j.field("bytes_on_disk", store.bytes_on_disk());
  j.key("minimum_cache_mb").begin_object();
  for (const MinimumBudgetRow& row : minimum_budgets(m)) j.field(row.accel, row.minimum.mib());
  j.end_object();
  const ProxyInfo proxies = proxy_info(store);
  j.key("proxies").begin_object().field("state", proxies.state);
  if (proxies.state == "valid" || proxies.state == "stale") {
    j.field("resolution", proxies.header.resolution).field("active_voxels", proxies.header.active_voxels);
    j.field("memory_bytes", proxies.header.memory_bytes).field("file_bytes", proxies.file_bytes);
  }
  j.end_object();
  j.end_object();
  return j.str();
}

void print_info(const SceneStore& store) {
  const Manifest& m = store.manifest();
  const BrickSizeStats sizes = brick_size_stats(m);
  std::printf("scene store   %s (format %u, packed by outcore %s)\n", store.directory().c_str(),
              m.format_version, m.outcore_version.c_str());
  std::printf("inputs        %zu\n", m.inputs.size());
  for (size_t i = 0; i < m.inputs.size(); ++i) {
    std::printf("  [%zu] %s: %llu triangles (%llu degenerate)\n", i, m.inputs[i].spec.c_str(),
                static_cast<unsigned long long>(m.inputs[i].triangle_count),
                static_cast<unsigned long long>(m.inputs[i].degenerate_count));
  }
  std::printf("triangles     %llu (%llu degenerate)\n", static_cast<unsigned long long>(m.triangle_count),
              static_cast<unsigned long long>(m.degenerate_count));
  std::printf("bounds        [%g %g %g] .. [%g %g %g]\n", m.bounds.lo.x, m.bounds.lo.y, m.bounds.lo.z,
              m.bounds.hi.x, m.bounds.hi.y, m.bounds.hi.z);
  std::printf("bricks        %zu (target <= %u triangles)\n", m.bricks.size(), m.brick_triangles_target);
  std::printf("  triangles   min %u, p10 %u, median %u, p90 %u, max %u, mean %.1f\n", sizes.min, sizes.p10,
              sizes.median, sizes.p90, sizes.max, sizes.mean);
  std::printf("upper BVH     %zu nodes, depth %u\n", m.upper.nodes.size(), m.upper.depth());
  std::printf("on disk       %s\n", human_bytes(static_cast<double>(store.bytes_on_disk())).c_str());
  std::string budgets;
  for (const MinimumBudgetRow& row : minimum_budgets(m))
    budgets += (budgets.empty() ? "" : ", ") + std::to_string(row.minimum.mib()) + " MiB (" + row.accel + ")";
  std::printf("min cache     %s: the smallest --cache-mb\n", budgets.c_str());
  const ProxyInfo proxies = proxy_info(store);
  if (proxies.state == "valid" || proxies.state == "stale") {
    std::printf("proxies       %s: resolution %u, %llu voxels, %s resident, %s on disk\n",
                proxies.state.c_str(), proxies.header.resolution,
                static_cast<unsigned long long>(proxies.header.active_voxels),
                human_bytes(static_cast<double>(proxies.header.memory_bytes)).c_str(),
                human_bytes(static_cast<double>(proxies.file_bytes)).c_str());
  } else {
    std::printf("proxies       %s (built on the first trace or serve)\n", proxies.state.c_str());
  }
}

}  // namespace

void add_info_command(CLI::App& app, int& exit_code) {
  auto path = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand("info", "Describe a scene store");
  cmd->add_option("scene", *path, "Scene store directory")->required();
  cmd->add_flag("--json", *json, "Machine-readable output");
  cmd->callback([path, json, &exit_code] {
    const auto store = SceneStore::open(*path);
    if (!store.ok()) {
      exit_code = report_command_error("info", store.status().message());
      return;
    }
    if (*json) {
      std::printf("%s\n", info_json(**store).c_str());
    } else {
      print_info(**store);
    }
    exit_code = 0;
  });
}

}  // namespace outcore
