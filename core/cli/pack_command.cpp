#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <cstdio>
#include <limits>
#include <memory>

#include "core/cli/commands.h"
#include "core/gen/generator_factory.h"
#include "core/store/scene_packer.h"
#include "core/util/cancellation.h"
#include "core/util/progress.h"

namespace outcore {

int report_command_error(const char* command, const std::string& message) {
  std::fprintf(stderr, "outcore %s: error: %s\n", command, message.c_str());
  return 1;
}

void add_pack_command(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<PackOptions>();
  auto quiet = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand("pack", "Pack triangle inputs into an on-disk scene store");
  std::string generators;
  for (const auto& name : generator_names()) generators += (generators.empty() ? "" : ", ") + name;
  cmd->add_option("inputs", options->inputs,
                  "Inputs: .obj, .ply, or gen:NAME?key=value&... (generators: " + generators +
                      "). geometry_id = position in this list")
      ->required();
  cmd->add_option("-o,--output", options->output, "Scene store directory to create")->required();
  auto brick_triangles = std::make_shared<uint32_t>(0);
  CLI::Option* brick_option = cmd->add_option(
      "--brick-tris", *brick_triangles,
      "Most triangles in one brick (default " + std::to_string(kDefaultBrickTriangles) +
          "; a scene of at most " + std::to_string(kSmallSceneTriangles) + " triangles is then one brick)");
  cmd->add_option("--mem-mb", options->memory_mb, "Peak memory bound for packing, MiB")
      ->check(CLI::Range(uint64_t{1}, std::numeric_limits<uint64_t>::max() >> 20))
      ->capture_default_str();
  cmd->add_option("--vertex-mem-mb", options->vertex_memory_mb,
                  "Part of --mem-mb for OBJ/PLY vertex positions, MiB (0: an eighth); files with more "
                  "resolve their faces out of core")
      ->check(CLI::Range(uint64_t{0}, std::numeric_limits<uint64_t>::max() >> 20))
      ->capture_default_str();
  cmd->add_flag("--force", options->overwrite,
                "Replace an existing Outcore store at the output path (never anything else, nor an input)");
  cmd->add_flag("--strict", options->strict, "An input that yields no triangles is an error, not a warning");
  auto no_sync = std::make_shared<bool>(false);
  cmd->add_flag("--no-sync", *no_sync, "Skip fsync before the final rename (faster, not durable)");
  cmd->add_flag("-q,--quiet", *quiet, "No progress bars");
  cmd->callback([options, quiet, no_sync, brick_triangles, brick_option, &exit_code] {
    if (brick_option->count() > 0) options->brick_triangles = *brick_triangles;
    options->show_progress = !*quiet;
    options->sync = !*no_sync;
    install_cancel_signal_handlers();
    // Warnings (stale temporary directories removed, empty inputs) go beside
    // the errors, not into the summary on stdout.
    spdlog::set_default_logger(spdlog::stderr_color_mt("outcore-pack"));
    const auto result = pack_scene(*options);
    if (!result.ok()) {
      exit_code = report_command_error("pack", result.status().message());
      return;
    }
    const PackSummary& s = *result;
    std::printf("packed %llu triangles (%llu degenerate, kept) from %zu input%s into %u bricks\n",
                static_cast<unsigned long long>(s.triangles),
                static_cast<unsigned long long>(s.degenerate_triangles), options->inputs.size(),
                options->inputs.size() == 1 ? "" : "s", s.bricks);
    std::printf("  brick triangles  min %u / median %u / max %u (target <= %u)\n", s.min_brick_triangles,
                s.median_brick_triangles, s.max_brick_triangles, s.brick_triangles_target);
    std::printf("  store            %s, %s on disk, upper hierarchy depth %u\n", options->output.c_str(),
                human_bytes(static_cast<double>(s.bytes_on_disk)).c_str(), s.upper_depth);
    std::printf("  time             %.2f s, %.2f M tris/s\n", s.seconds,
                s.triangles / 1e6 / std::max(s.seconds, 1e-9));
    std::printf("  memory           peak RSS %s (bound --mem-mb %llu), out-of-core levels %u, spill %s\n",
                human_bytes(static_cast<double>(s.peak_rss_bytes)).c_str(),
                static_cast<unsigned long long>(options->memory_mb), s.out_of_core_levels,
                human_bytes(static_cast<double>(s.spill_bytes_written)).c_str());
    const PackPhaseSeconds& p = s.phases;
    std::printf(
        "  phases           scan %.2f s, histogram %.2f s, fill %.2f s, bricks %.2f s (waiting for the disk "
        "%.2f s), finish %.2f s\n",
        p.scan, p.histogram, p.fill, p.bricks, p.write_wait, p.finish);
    exit_code = 0;
  });
}

}  // namespace outcore
