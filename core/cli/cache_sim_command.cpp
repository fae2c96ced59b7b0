// `outcore cache-sim TRACE`: replays a brick access trace (recorded with
// `outcore trace --trace-out`) against eviction policies and cache budgets,
// next to Belady's offline optimum, and prints (or writes as JSON and PNG)
// misses, miss ratio, bytes built and build seconds per policy and budget.
// See docs/CACHE_TUNING.md.
#include <tbb/parallel_for.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "core/cache/access_trace.h"
#include "core/cache/belady.h"
#include "core/cache/cache_simulator.h"
#include "core/cache/eviction_policy.h"
#include "core/cli/commands.h"
#include "core/util/json_writer.h"
#include "core/util/line_plot.h"
#include "core/util/png_writer.h"

namespace outcore {
namespace {

struct CacheSimArgs {
  std::string trace_path;
  std::string policy = "all";
  std::string budget_mb;
  std::string budget_fractions;
  std::string png_path;
  bool json = false;
};

constexpr const char* kDefaultFractions = "0.0625,0.125,0.25,0.5,1";

Expected<std::vector<double>> parse_list(const std::string& option, const std::string& text) {
  std::vector<double> values;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    double v = 0;
    std::size_t used = 0;
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size() || !std::isfinite(v) || v <= 0)
      return invalid_argument(option + " '" + item + "' is not a positive number");
    values.push_back(v);
  }
  if (values.empty()) return invalid_argument(option + " needs at least one value");
  std::sort(values.begin(), values.end());
  values.erase(std::unique(values.begin(), values.end()), values.end());
  return values;
}

Expected<std::vector<std::string>> parse_policies(const std::string& text) {
  if (text == "all") return eviction_policy_names();
  std::vector<std::string> names;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    OUTCORE_RETURN_IF_ERROR(make_eviction_policy(item).status());  // names the known ones
    if (std::find(names.begin(), names.end(), item) == names.end()) names.push_back(item);
  }
  if (names.empty()) return invalid_argument("--policy needs a policy name or 'all'");
  return names;
}

// %g: the number as the user would write it back.
std::string format_number(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", value);
  return text;
}

double mib(uint64_t bytes) {
  return static_cast<double>(bytes) / 1048576.0;
}

int run_cache_sim(const CacheSimArgs& args) {
  constexpr const char* kCommand = "cache-sim";
  if (!args.budget_mb.empty() && !args.budget_fractions.empty())
    return report_command_error(kCommand, "give either --budget-mb or --budget-fractions, not both");
  auto policies = parse_policies(args.policy);
  if (!policies.ok()) return report_command_error(kCommand, policies.status().message());
  auto trace = read_access_trace(args.trace_path);
  if (!trace.ok()) return report_command_error(kCommand, trace.status().message());
  if (trace->records.empty()) return report_command_error(kCommand, args.trace_path + " has no records");
  const TraceProfile profile = TraceProfile::of(*trace);

  std::vector<uint64_t> budgets;
  if (!args.budget_mb.empty()) {
    auto values = parse_list("--budget-mb", args.budget_mb);
    if (!values.ok()) return report_command_error(kCommand, values.status().message());
    constexpr double kMaxMiB = static_cast<double>(kMaxTraceBytes >> 20);
    for (double v : *values) {
      // Checked before the conversion: llround of a value past 2^63 is undefined.
      if (v > kMaxMiB) {
        return report_command_error(kCommand, "--budget-mb " + format_number(v) + " is more than " +
                                                  format_number(kMaxMiB) + " MiB (2^62 bytes)");
      }
      const auto budget = static_cast<uint64_t>(std::llround(v * 1048576.0));
      if (budget == 0) {
        return report_command_error(kCommand, "--budget-mb " + format_number(v) + " is less than one byte");
      }
      budgets.push_back(budget);
    }
  } else {
    const bool defaulted = args.budget_fractions.empty();
    auto values = parse_list("--budget-fractions", defaulted ? kDefaultFractions : args.budget_fractions);
    if (!values.ok()) return report_command_error(kCommand, values.status().message());
    for (double v : *values) {
      const double bytes = v * static_cast<double>(profile.working_set_bytes);
      if (bytes > static_cast<double>(kMaxTraceBytes)) {
        return report_command_error(
            kCommand, "--budget-fractions " + format_number(v) + " of the working set (" +
                          std::to_string(profile.working_set_bytes) + " bytes) is more than 2^62 bytes");
      }
      const auto budget = static_cast<uint64_t>(std::llround(bytes));
      // Default fractions below what the largest brick needs are skipped, not errors.
      if (defaulted && budget < profile.largest_reservation) {
        std::fprintf(stderr,
                     "outcore cache-sim: skipping budget fraction %g (%.2f MiB): brick %u needs %.2f MiB\n",
                     v, mib(budget), profile.largest_brick_id, mib(profile.largest_reservation));
        continue;
      }
      budgets.push_back(budget);
    }
    if (budgets.empty()) budgets.push_back(profile.largest_reservation);
  }
  // Every path above yields a budget or an error; an empty table with exit
  // status 0 would read as a successful replay.
  if (budgets.empty())
    return report_command_error(kCommand, "no cache budget to replay " + args.trace_path + " with");
  for (const uint64_t budget : budgets) {
    const Status fits = check_budget(*trace, profile, budget);
    if (!fits.ok()) return report_command_error(kCommand, fits.message());
  }

  // One job per (budget, policy); the last column of each budget is OPT.
  const std::size_t columns = policies->size() + 1;
  std::vector<Expected<SimulationResult>> results(budgets.size() * columns,
                                                  Status(StatusCode::kInternal, "not run"));
  tbb::parallel_for(std::size_t{0}, results.size(), [&](std::size_t job) {
    const uint64_t budget = budgets[job / columns];
    const std::size_t column = job % columns;
    results[job] = column < policies->size() ? simulate_policy(*trace, profile, (*policies)[column], budget)
                                             : simulate_opt(*trace, profile, budget);
  });
  for (const auto& r : results) {
    if (!r.ok()) return report_command_error(kCommand, r.status().message());
  }
  const auto result = [&](std::size_t b, std::size_t c) -> const SimulationResult& {
    return *results[b * columns + c];
  };

  if (args.json) {
    JsonWriter j;
    j.begin_object();
    j.field("trace", args.trace_path).field("requests", uint64_t{trace->records.size()});
    j.field("distinct_bricks", profile.distinct_bricks).field("working_set_bytes", profile.working_set_bytes);
    j.field("recorded_policy", trace->info.policy).field("recorded_budget_bytes", trace->info.budget_bytes);
    j.key("results").begin_array();
    for (std::size_t b = 0; b < budgets.size(); ++b) {
      for (std::size_t c = 0; c < columns; ++c) {
        const SimulationResult& r = result(b, c);
        const SimulationResult& opt = result(b, columns - 1);
        j.begin_object();
        j.field("policy", r.policy);
        if (!r.detail.empty()) j.field("rule", r.detail);
        j.field("budget_bytes", r.budget_bytes).field("requests", r.requests).field("hits", r.hits);
        j.field("misses", r.misses).field("miss_ratio", r.miss_ratio()).field("evictions", r.evictions);
        j.field("bytes_built", r.bytes_built).field("build_seconds", r.build_seconds);
        j.field("misses_vs_opt",
                opt.misses ? static_cast<double>(r.misses) / static_cast<double>(opt.misses) : 1.0);
        j.end_object();
      }
    }
    j.end_array().end_object();
    std::printf("%s\n", j.str().c_str());
  } else {
    std::printf("trace %s: %zu requests, %u distinct bricks, working set %.2f MiB", args.trace_path.c_str(),
                trace->records.size(), profile.distinct_bricks, mib(profile.working_set_bytes));
    if (!trace->info.policy.empty())
      std::printf(" (recorded with %s at %.2f MiB)", trace->info.policy.c_str(),
                  mib(trace->info.budget_bytes));
    std::printf("\n%11s  %-7s %10s %10s %12s %12s %8s\n", "budget_MiB", "policy", "misses", "miss_ratio",
                "built_MiB", "build_s", "vs_opt");
    for (std::size_t b = 0; b < budgets.size(); ++b) {
      const SimulationResult& opt = result(b, columns - 1);
      for (std::size_t c = 0; c < columns; ++c) {
        const SimulationResult& r = result(b, c);
        const double ratio =
            opt.misses ? static_cast<double>(r.misses) / static_cast<double>(opt.misses) : 1.0;
        std::printf("%11.2f  %-7s %10llu %10.4f %12.2f %12.4f %8.3f\n", mib(r.budget_bytes), r.policy.c_str(),
                    static_cast<unsigned long long>(r.misses), r.miss_ratio(), mib(r.bytes_built),
                    r.build_seconds, ratio);
      }
    }
    std::printf(
        "opt: Belady (furthest next use; exact for equal brick sizes, best of it and a size-aware\n"
        "rule otherwise). vs_opt: misses / OPT's misses.\n");
  }

  if (!args.png_path.empty()) {
    std::vector<PlotSeries> series(columns);
    for (std::size_t c = 0; c < columns; ++c) {
      series[c].name = c + 1 < columns ? (*policies)[c] : "opt (Belady)";
      series[c].dashed = c + 1 == columns;
      for (std::size_t b = 0; b < budgets.size(); ++b) {
        series[c].x.push_back(mib(budgets[b]));
        series[c].y.push_back(result(b, c).miss_ratio());
      }
    }
    LinePlotConfig plot;
    plot.title = "Brick cache miss ratio by budget: " + std::to_string(trace->records.size()) +
                 " requests, " + std::to_string(profile.distinct_bricks) + " bricks";
    plot.x_label = "cache budget (MiB, log scale)";
    plot.y_label = "miss ratio (builds / requests)";
    plot.log_x = budgets.size() > 1;
    auto image = render_line_plot(series, plot);
    if (!image.ok()) return report_command_error(kCommand, image.status().message());
    const Status written = write_png(args.png_path, image->width, image->height, image->pixels);
    if (!written.ok()) return report_command_error(kCommand, written.message());
  }
  return 0;
}

}  // namespace

void add_cache_sim_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<CacheSimArgs>();
  CLI::App* cmd =
      app.add_subcommand("cache-sim", "Replay a brick access trace against cache policies and budgets");
  cmd->add_option("trace", args->trace_path, "Access trace CSV from `outcore trace --trace-out`")->required();
  cmd->add_option("--policy", args->policy, "Policy name, comma-separated names, or 'all'")
      ->capture_default_str();
  cmd->add_option("--budget-mb", args->budget_mb, "Cache budgets in MiB, comma-separated");
  cmd->add_option("--budget-fractions", args->budget_fractions,
                  std::string("Budgets as fractions of the trace's working set, comma-separated (default ") +
                      kDefaultFractions + ")");
  cmd->add_option("--png", args->png_path, "Write a plot of miss ratio against budget to this PNG");
  cmd->add_flag("--json", args->json, "Print the results as one JSON object");
  cmd->callback([args, &exit_code] { exit_code = run_cache_sim(*args); });
}

}  // namespace outcore
