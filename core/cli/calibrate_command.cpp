// `outcore calibrate [STORE]`: measures every brick structure's build and
// trace cost on sample bricks (of STORE, or of built-in scenes) and writes
// the cost profile `--brick-accel auto` reads (core/calibrate/calibration.h,
// core/accel/auto/cost_profile.h).
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/accel/auto/auto_brick.h"
#include "core/calibrate/calibration.h"
#include "core/cli/commands.h"
#include "core/util/progress.h"

namespace outcore {
namespace {

struct CalibrateArgs {
  std::string store;
  std::string profile;
  std::string structures;
  std::string triangle_test;
  uint32_t bricks = 12;
  uint32_t rays = 4096;
  bool quiet = false;
  bool evaluate = false;
};

std::vector<std::string> split_commas(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string item; std::getline(in, item, ',');) out.push_back(item);
  return out;
}

// How often `profile`'s choice is within 10 % of the measured best (build
// + rays x trace, both measured) over the samples at a few ray counts.
struct Agreement {
  int within = 0, cases = 0;
};

Agreement agreement(const Calibration& c, const CostProfile& profile) {
  Agreement a;
  const uint64_t ray_counts[] = {0, 1000, 10000, 100000, 1000000, 10000000};
  for (const uint64_t rays : ray_counts) {
    for (const CalibrationSample& sample : c.samples) {
      double measured_min = INFINITY, predicted_min = INFINITY, chosen_cost = INFINITY;
      for (std::size_t s = 0; s < c.structures.size(); ++s) {
        const StructureCost* cost = profile.find(c.structures[s]);
        const double m = sample.measures[s].build_seconds + rays * sample.measures[s].trace_seconds_per_ray;
        measured_min = std::min(measured_min, m);
        if (cost == nullptr) continue;
        const double p =
            cost->build_seconds(sample.features) + rays * cost->trace_seconds_per_ray(sample.features);
        if (p < predicted_min) predicted_min = p, chosen_cost = m;
      }
      ++a.cases;
      a.within += chosen_cost <= 1.1 * measured_min;
    }
  }
  return a;
}

void print_table(const Calibration& c) {
  std::printf("%-58s %9s", "sample", "triangles");
  for (const std::string& s : c.structures) std::printf(" %10s", s.c_str());
  std::printf("\n");
  for (const CalibrationSample& sample : c.samples) {
    std::printf("%-58.58s %9u", sample.label.c_str(), sample.features.triangles);
    for (const StructureMeasure& m : sample.measures) std::printf(" %7.2f ms", m.build_seconds * 1e3);
    std::printf("   build\n%-58s %9s", "", "");
    for (const StructureMeasure& m : sample.measures) std::printf(" %7.0f ns", m.trace_seconds_per_ray * 1e9);
    std::printf("   trace per ray\n");
  }
}

void print_agreement(const char* what, const Agreement& a) {
  std::printf(
      "%s: its choice is within 10%% of the measured best in %d of %d (brick, rays) cases (%.0f%%; rays "
      "0, 1k, 10k, 100k, 1M, 10M)\n",
      what, a.within, a.cases, a.cases ? 100.0 * a.within / a.cases : 0.0);
}

int run_calibrate(const CalibrateArgs& args) {
  CalibrationOptions options;
  if (!args.structures.empty()) options.structures = split_commas(args.structures);
  if (!args.triangle_test.empty()) options.structure_options["triangle_test"] = args.triangle_test;
  options.rays_per_brick = args.rays;
  Expected<std::vector<SampleBrick>> samples = [&]() -> Expected<std::vector<SampleBrick>> {
    if (args.store.empty()) return builtin_sample_bricks();
    OUTCORE_ASSIGN_OR_RETURN(std::shared_ptr<const SceneStore> store, SceneStore::open(args.store));
    return sample_store_bricks(*store, args.bricks);
  }();
  if (!samples.ok()) return report_command_error("calibrate", samples.status().to_string());
  const std::size_t structure_count =
      options.structures.empty() ? std::size(kDefaultAutoCandidates) : options.structures.size();
  ProgressBar progress("calibrate", samples->size() * structure_count, "measures", !args.quiet);
  options.on_measured = [&progress] { progress.advance(1); };
  const auto start = std::chrono::steady_clock::now();
  Expected<Calibration> calibration = calibrate(std::move(samples).value(), options);
  progress.finish();
  if (!calibration.ok()) return report_command_error("calibrate", calibration.status().to_string());
  if (args.evaluate) {
    // The profile auto would use now, judged on these bricks; nothing written.
    Expected<CostProfile> current = resolve_cost_profile(args.profile);
    if (!current.ok()) return report_command_error("calibrate", current.status().to_string());
    if (!args.quiet) print_table(*calibration);
    print_agreement(("profile " + current->origin).c_str(), agreement(*calibration, *current));
    print_agreement("a profile fitted to these bricks", agreement(*calibration, calibration->profile));
    return 0;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  CostProfile profile = calibration->profile;
  char host[256] = "unknown";
  if (FILE* f = std::fopen("/proc/sys/kernel/hostname", "r")) {
    if (std::fgets(host, sizeof(host), f) == nullptr) host[0] = 0;
    std::fclose(f);
    host[std::strcspn(host, "\n")] = 0;
  }
  profile.machine = std::string(host) + ", " + std::to_string(calibration->samples.size()) + " samples of " +
                    (args.store.empty() ? std::string("built-in scenes") : args.store) + ", " +
                    std::to_string(std::thread::hardware_concurrency()) + " threads";
  const std::string path = args.profile.empty() ? default_cost_profile_path() : args.profile;
  if (path.empty())
    return report_command_error("calibrate", "no --profile given and no HOME to write one in");
  std::error_code ec;
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent, ec);
  const Status saved = save_cost_profile(profile, path);
  if (!saved.ok()) return report_command_error("calibrate", saved.to_string());
  if (!args.quiet) {
    print_table(*calibration);
    print_agreement("fit", agreement(*calibration, profile));
  }
  std::printf("calibrated %zu structures on %zu sample bricks in %.1f s; profile written to %s\n",
              calibration->structures.size(), calibration->samples.size(), seconds, path.c_str());
  return 0;
}

}  // namespace

void add_calibrate_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<CalibrateArgs>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Measure each brick structure's build and trace cost here and write the cost profile of "
      "--brick-accel auto");
  cmd->add_option("store", args->store,
                  "Scene store whose bricks to sample (default: built-in procedural scenes)");
  cmd->add_option("--profile", args->profile,
                  "Profile file to write (default: $OUTCORE_COST_PROFILE, else "
                  "$XDG_CONFIG_HOME/outcore/cost_profile.txt, XDG_CONFIG_HOME defaulting to ~/.config)");
  cmd->add_option("--structures", args->structures,
                  "Structures to measure, comma-separated (default: auto's candidates)");
  cmd->add_option("--triangle-test", args->triangle_test,
                  "Triangle test of every structure (default watertight)");
  cmd->add_option("--bricks", args->bricks, "Sample bricks of STORE, spread over its brick sizes")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--rays", args->rays, "Incoherent rays traced per sample brick")
      ->capture_default_str()
      ->check(CLI::Range(16, 1 << 22));
  cmd->add_flag("--evaluate", args->evaluate,
                "Write nothing: measure, then say how often the current profile (--profile, else the default "
                "one) chooses within 10% of the measured best on these bricks");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress bar and no table");
  cmd->callback([args, &exit_code] { exit_code = run_calibrate(*args); });
}

}  // namespace outcore
