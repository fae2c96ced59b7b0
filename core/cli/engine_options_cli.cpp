#include "core/cli/engine_options_cli.h"

#include <CLI/CLI.hpp>

#include <limits>
#include <string>

#include "core/accel/bvh/wide_bvh_trace.h"

namespace outcore {

namespace {

constexpr uint64_t kMaxCacheMiB = std::numeric_limits<uint64_t>::max() >> 20;

Expected<BrickAccelOptions> parse_accel_options(const std::vector<std::string>& items) {
  BrickAccelOptions options;
  for (const std::string& item : items) {
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      return invalid_argument("--accel-opt '" + item + "' is not of the form key=value");
    }
    if (!options.emplace(item.substr(0, eq), item.substr(eq + 1)).second) {
      return invalid_argument("--accel-opt '" + item.substr(0, eq) + "' given twice");
    }
  }
  return options;
}

Status apply_proxy_options(const EngineCliOptions& cli, EngineOptions& options) {
  if (cli.no_proxies && cli.proxy_res) {
    return invalid_argument("--proxy-res has no effect with --no-proxies; give one of them");
  }
  options.proxies = !cli.no_proxies;
  if (cli.proxy_res) {
    if (*cli.proxy_res < kMinProxyResolution || *cli.proxy_res > kMaxProxyResolution) {
      return invalid_argument("--proxy-res must be between " + std::to_string(kMinProxyResolution) + " and " +
                              std::to_string(kMaxProxyResolution) + ", got " +
                              std::to_string(*cli.proxy_res));
    }
    options.proxy_config.resolution = static_cast<uint32_t>(*cli.proxy_res);
  }
  return Status::Ok();
}

// Whether the structure takes the triangle_test option (asked of the factory,
// so a new structure needs no change here).
bool takes_triangle_test(const std::string& brick_accel) {
  return make_brick_builder(brick_accel, {{"triangle_test", "watertight"}}).ok();
}

// --triangle-test and --reference, once options.accel_options holds --accel-opt.
Status apply_brick_structure_choices(const EngineCliOptions& cli, EngineOptions& options) {
  if (!cli.triangle_test.empty()) {
    if (!takes_triangle_test(cli.brick_accel)) {
      std::string takers;
      for (const std::string& name : brick_accel_names()) {
        if (takes_triangle_test(name)) takers += (takers.empty() ? "" : "|") + name;
      }
      return invalid_argument("--triangle-test needs --brick-accel " + takers + " (got '" + cli.brick_accel +
                              "')");
    }
    if (!options.accel_options.emplace("triangle_test", cli.triangle_test).second) {
      return invalid_argument("--triangle-test and --accel-opt triangle_test=... both given");
    }
  }
  if (!cli.profile.empty()) {
    if (cli.brick_accel != "auto") {
      return invalid_argument("--profile is the cost profile of --brick-accel auto (got '" + cli.brick_accel +
                              "')");
    }
    if (!options.accel_options.emplace("profile", cli.profile).second) {
      return invalid_argument("--profile and --accel-opt profile=... both given");
    }
  }
  if (cli.reference) {
    if (cli.brick_accel != kDefaultBrickAccel || !cli.accel_options.empty() || !cli.triangle_test.empty() ||
        !cli.profile.empty()) {
      return invalid_argument(
          "--reference chooses the brick structure itself: drop --brick-accel, --accel-opt and "
          "--triangle-test");
    }
    options.brick_accel = "reference";
  }
  return Status::Ok();
}

}  // namespace

void add_cache_options(CLI::App& command, EngineCliOptions& options) {
  // A range check here names the value as given: "-1" would otherwise wrap
  // to 2^64 - 1 before apply_engine_options() sees it.
  command.add_option("--cache-mb", options.cache_mb, "Byte budget of the brick cache, MiB")
      ->check(CLI::Range(uint64_t{1}, kMaxCacheMiB))
      ->capture_default_str();
  command.add_option("--policy", options.policy, "Cache eviction policy")->capture_default_str();
  command.add_option("--brick-accel", options.brick_accel, "Brick structure")->capture_default_str();
  command.add_option(
      "--profile", options.profile,
      "Cost profile of --brick-accel auto (from `outcore calibrate`; default: "
      "$OUTCORE_COST_PROFILE, else $XDG_CONFIG_HOME/outcore/cost_profile.txt if it exists, else "
      "built-in)");
  command
      .add_option("--brick-bounds", options.brick_bounds,
                  "Bound tested before a brick beyond the upper hierarchy's box: aabb (none), sphere or obb "
                  "(fitted at pack time; answers are the same, brick visits without a hit fewer)")
      ->capture_default_str();
  command
      .add_option(
          "--dynamic-top", options.dynamic_top_level,
          "Structure over the dynamic layer's instances: bvh (8-wide, refitted) or bkd (the B-KD tree); "
          "answers are the same")
      ->capture_default_str();
  add_subtree_options(command, options.subtree);
}

Status apply_engine_options(const EngineCliOptions& cli, EngineOptions& options) {
  auto accel_options = parse_accel_options(cli.accel_options);
  if (!accel_options.ok()) return accel_options.status();
  if (cli.cache_mb == 0 || cli.cache_mb > kMaxCacheMiB) {
    return invalid_argument("--cache-mb must be between 1 and " + std::to_string(kMaxCacheMiB) + ", got " +
                            std::to_string(cli.cache_mb));
  }
  OUTCORE_RETURN_IF_ERROR(apply_proxy_options(cli, options));
  // The bvh bricks' SIMD path is chosen once per process; a bad
  // OUTCORE_SIMD is an error here rather than a silent fallback later.
  const Expected<SimdPath> simd = simd_path_from_environment();
  if (!simd.ok()) return simd.status();
  options.cache_bytes = cli.cache_mb << 20;
  options.eviction_policy = cli.policy;
  options.brick_accel = cli.brick_accel;
  options.accel_options = *accel_options;
  if (!brick_bound_from_name(cli.brick_bounds)) {
    return invalid_argument("--brick-bounds must be aabb, sphere or obb, got '" + cli.brick_bounds + "'");
  }
  options.brick_bounds = cli.brick_bounds;
  if (cli.dynamic_top_level != "bvh" && cli.dynamic_top_level != "bkd")
    return invalid_argument("--dynamic-top must be bvh or bkd, got '" + cli.dynamic_top_level + "'");
  options.dynamic_top_level = cli.dynamic_top_level;
  // --reference names the structure, which the subtree check needs.
  OUTCORE_RETURN_IF_ERROR(apply_brick_structure_choices(cli, options));
  return apply_subtree_options(cli.subtree, options);
}

}  // namespace outcore
