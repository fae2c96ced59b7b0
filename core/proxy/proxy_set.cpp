#include "core/proxy/proxy_set.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <chrono>

#include "core/proxy/proxy_file.h"

namespace outcore {

namespace {
using Clock = std::chrono::steady_clock;
}

ProxySet::ProxySet(const ProxyBuildConfig& config, std::vector<BrickProxy> proxies)
    : config_(config), proxies_(std::move(proxies)) {
  for (const BrickProxy& p : proxies_) {
    memory_bytes_ += p.memory_bytes();
    active_voxels_ += p.active_voxels();
  }
  memory_bytes_ += proxies_.capacity() * sizeof(BrickProxy) + sizeof(ProxySet);
}

Expected<std::unique_ptr<const ProxySet>> ProxySet::build(const SceneStore& store,
                                                          const ProxyBuildConfig& config) {
  OUTCORE_RETURN_IF_ERROR(validate_proxy_config(config));
  const uint32_t n = store.brick_count();
  std::vector<BrickProxy> proxies(n);
  std::vector<Status> errors(n);
  // One brick per task: a brick is loaded (and its memory held) only while
  // its proxy is built.
  tbb::parallel_for(uint32_t{0}, n, [&](uint32_t b) {
    BrickData data;
    errors[b] = store.load_brick(b, data);
    if (errors[b].ok())
      proxies[b] = build_brick_proxy(store.manifest().bricks[b].bounds, store.manifest().bounds,
                                     data.triangles, config);
  });
  // A brick that cannot be read gets no proxy (it is never skipped), so the
  // query that needs it reports the error, as without proxies.
  uint32_t missing = 0;
  for (uint32_t b = 0; b < n; ++b) {
    if (errors[b].ok()) continue;
    if (missing++ == 0) spdlog::warn("brick proxies: {}; that brick is never skipped", errors[b].message());
  }
  auto set = std::unique_ptr<ProxySet>(new ProxySet(config, std::move(proxies)));
  set->bricks_without_proxy_ = missing;
  return std::unique_ptr<const ProxySet>(std::move(set));
}

Expected<std::unique_ptr<const ProxySet>> ProxySet::open(const SceneStore& store,
                                                         const ProxyBuildConfig& config,
                                                         ProxyOpenReport* report_out) {
  OUTCORE_RETURN_IF_ERROR(validate_proxy_config(config));
  const auto start = Clock::now();
  ProxyOpenReport report;
  const std::string path = store.directory() + "/" + kProxyFileName;
  auto loaded = read_proxy_file(path, store.manifest(), config);
  if (loaded.ok()) {
    report.loaded = true;
    report.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    if (report_out != nullptr) *report_out = report;
    return std::move(loaded).value();
  }
  report.rebuild_reason = loaded.status().message();
  if (loaded.status().code() == StatusCode::kDataLoss) {
    spdlog::warn("{}; rebuilding the brick proxies", report.rebuild_reason);
  }
  OUTCORE_ASSIGN_OR_RETURN(auto built, build(store, config));
  // An incomplete set is not cached: the next open tries those bricks again.
  const Status written =
      built->bricks_without_proxy() > 0
          ? data_loss(std::to_string(built->bricks_without_proxy()) + " bricks could not be read")
          : write_proxy_file(store.directory(), *built, store_fingerprint(store.manifest()));
  if (written.ok()) {
    report.written = true;
  } else {
    report.write_error = written.message();
    spdlog::warn("brick proxies kept in memory only: {}", written.message());
  }
  report.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  if (report_out != nullptr) *report_out = report;
  return built;
}

}  // namespace outcore
