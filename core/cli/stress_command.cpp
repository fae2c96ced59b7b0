// `outcore stress`: the numerical stress suite as a report (one table, a row
// per case and configuration; core/stress). Exit code 0 unless a
// configuration that must not leak (bvh-watertight, bvh-double, the kd-tree's
// and the BSP's) leaked or
// answered differently across brick seams, or the suite could not run.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

#include "core/cli/commands.h"
#include "core/stress/stress_runner.h"
#include "core/stress/stress_scenes.h"
#include "core/util/progress.h"

namespace outcore {
namespace {

struct StressArgs {
  std::string config = "all";
  bool quick = false;
  std::optional<std::string> models_dir;  // unset: find the repository's tests/data/models
  bool no_models = false;
  uint32_t stride = 1;
  uint32_t checked = 0;  // 0: 1000 with --quick, else 20000
  bool quiet = false;
};

namespace fs = std::filesystem;

// The stress models ship in the repository (tests/data/models). Where to look
// when --models is not given, so that the command works from any directory:
// $OUTCORE_MODELS_DIR, then the repository around the running binary (it
// lives in build*/client/ of a checkout), then the current directory's
// tests/data/models (the repository root).
std::vector<fs::path> default_model_dirs() {
  std::vector<fs::path> dirs;
  if (const char* env = std::getenv("OUTCORE_MODELS_DIR"); env != nullptr && *env != '\0')
    dirs.emplace_back(env);
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec)
    for (fs::path dir = exe.parent_path(); !dir.empty() && dir != dir.root_path(); dir = dir.parent_path())
      dirs.push_back(dir / "tests" / "data" / "models");
  dirs.push_back(fs::current_path(ec) / "tests" / "data" / "models");
  return dirs;
}

bool has_stress_models(const fs::path& dir) {
  std::error_code ec;
  return fs::is_regular_file(dir / "fandisk.obj", ec);
}

// The models directory in effect: --models as given (must exist), nothing
// with --no-models, else the first default that holds the models; an error
// listing where it looked otherwise, so a run never silently drops them.
Expected<std::string> resolve_models_dir(const StressArgs& args) {
  if (args.no_models) return std::string();
  if (args.models_dir) {
    std::error_code ec;
    if (!fs::is_directory(*args.models_dir, ec))
      return invalid_argument("--models " + *args.models_dir + ": not a directory");
    return *args.models_dir;
  }
  std::string looked;
  for (const fs::path& dir : default_model_dirs()) {
    if (has_stress_models(dir)) return dir.string();
    looked += "\n  " + dir.string();
  }
  return not_found(
      "the stress models (fandisk.obj, homer.obj, spot.obj, beast.obj) were not found; looked in:" + looked +
      "\npass --models DIR (the repository's tests/data/models), or --no-models for the generated cases "
      "only");
}

int run_stress_command(const StressArgs& args) {
  auto configs = select_stress_configs(args.config);
  if (!configs.ok()) return report_command_error("stress", configs.status().message());
  if (args.stride == 0) return report_command_error("stress", "--stride must be at least 1");
  auto models_dir = resolve_models_dir(args);
  if (!models_dir.ok()) return report_command_error("stress", models_dir.status().message());
  StressOptions options;
  options.quick = args.quick;
  options.models_dir = *models_dir;
  options.stride = args.stride;
  const auto start = std::chrono::steady_clock::now();
  auto scenes = make_stress_scenes(options);
  if (!scenes.ok()) return report_command_error("stress", scenes.status().message());
  const uint32_t max_checked = args.checked != 0 ? args.checked : (args.quick ? 1000 : 20000);
  std::vector<StressRow> rows;
  bool failed = false;
  ProgressStyle style;
  style.show_after = kShowProgressAfter;
  ProgressBar progress("stress", scenes->scenes.size() * configs->size(), "cases", !args.quiet, stderr,
                       std::move(style));
  ProgressTicker ticker(progress);
  for (const StressScene& scene : scenes->scenes) {
    const StressReference reference = compute_stress_reference(scene, max_checked);
    for (const StressConfig& config : *configs) {
      auto row = run_stress(scene, reference, config);
      if (!row.ok())
        return report_command_error("stress",
                                    scene.name + ", " + config.name + ": " + row.status().message());
      if (config.must_not_leak && (row->leaks != 0 || row->seam_diffs > 0)) failed = true;
      rows.push_back(*row);
      progress.advance(1);
    }
  }
  progress.finish();
  std::fputs(format_stress_table(rows).c_str(), stdout);
  for (const std::string& note : scenes->notes) std::printf("note: %s\n", note.c_str());
  std::printf("%zu cases x %zu configurations in %.1f s\n", scenes->scenes.size(), configs->size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  if (failed)
    return report_command_error("stress", "a watertight configuration leaked or differed across brick seams");
  return 0;
}

}  // namespace

void add_stress_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<StressArgs>();
  CLI::App* cmd = app.add_subcommand("stress", "Numerical stress suite: leaks and errors per configuration");
  cmd->add_option("--config", args->config,
                  "all, embree, embree-robust, bvh-mt, bvh-watertight, bvh-double, kdtree-watertight, "
                  "kdtree-double, bsp-watertight, bsp-double, grid-watertight, grid-double, "
                  "hgrid-watertight, hgrid-double, "
                  "octree-watertight, octree-double, quadtree-watertight or quadtree-double")
      ->capture_default_str();
  cmd->add_flag("--quick", args->quick, "Smaller generated meshes and fewer reference checks");
  auto* models =
      cmd->add_option("--models", args->models_dir,
                      "Directory with fandisk.obj, homer.obj, spot.obj, beast.obj (default: "
                      "$OUTCORE_MODELS_DIR, else the repository's tests/data/models found from the "
                      "binary's location or the current directory)");
  cmd->add_flag("--no-models", args->no_models, "Only the generated cases (no model files)")
      ->excludes(models);
  cmd->add_option("--stride", args->stride, "Aim at every N-th vertex and edge midpoint")
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", args->quiet, "No progress line on stderr (shown for runs over 2 s)");
  cmd->add_option("--checked", args->checked,
                  "Rays per case checked against the float64 brute force (default 1000 quick, 20000 full)");
  cmd->callback([args, &exit_code] { exit_code = run_stress_command(*args); });
}

}  // namespace outcore
