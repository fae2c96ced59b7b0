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

Expected<std::vector<uint64_t>> budgets_from_mb(const std::string& text) {
  OUTCORE_ASSIGN_OR_RETURN(const std::vector<double> values, parse_list("--budget-mb", text));
  constexpr double kMaxMiB = static_cast<double>(kMaxTraceBytes >> 20);
  std::vector<uint64_t> budgets;
  for (double v : values) {
    // Checked before the conversion: llround of a value past 2^63 is undefined.
    if (v > kMaxMiB) {
      return invalid_argument("--budget-mb " + format_number(v) + " is more than " + format_number(kMaxMiB) +
                              " MiB (2^62 bytes)");
    }
    const auto budget = static_cast<uint64_t>(std::llround(v * 1048576.0));
    if (budget == 0) return invalid_argument("--budget-mb " + format_number(v) + " is less than one byte");
    budgets.push_back(budget);
  }
  return budgets;
}

Expected<std::vector<uint64_t>> budgets_from_fractions(const std::string& text, const TraceProfile& profile) {
  const bool defaulted = text.empty();
  OUTCORE_ASSIGN_OR_RETURN(const std::vector<double> values,
                           parse_list("--budget-fractions", defaulted ? kDefaultFractions : text));
  std::vector<uint64_t> budgets;
  for (double v : values) {
    const double bytes = v * static_cast<double>(profile.working_set_bytes);
    if (bytes > static_cast<double>(kMaxTraceBytes)) {
      return invalid_argument("--budget-fractions " + format_number(v) + " of the working set (" +
                              std::to_string(profile.working_set_bytes) + " bytes) is more than 2^62 bytes");
    }
    const auto budget = static_cast<uint64_t>(std::llround(bytes));
    // Default fractions below what the largest brick needs are skipped, not errors.
    if (defaulted && budget < profile.largest_reservation) {
      std::fprintf(stderr,
                   "outcore cache-sim: skipping budget fraction %g (%.2f MiB): brick %u needs %.2f MiB\n", v,
                   mib(budget), profile.largest_brick_id, mib(profile.largest_reservation));
      continue;
    }
    budgets.push_back(budget);
  }
  if (budgets.empty()) budgets.push_back(profile.largest_reservation);
  return budgets;
}

// The budgets to replay, each checked against the trace.
Expected<std::vector<uint64_t>> choose_budgets(const CacheSimArgs& args, const AccessTrace& trace,
                                               const TraceProfile& profile) {
  OUTCORE_ASSIGN_OR_RETURN(std::vector<uint64_t> budgets,
                           !args.budget_mb.empty() ? budgets_from_mb(args.budget_mb)
                                                   : budgets_from_fractions(args.budget_fractions, profile));
  // Every path above yields a budget or an error; an empty table with exit
  // status 0 would read as a successful replay.
  if (budgets.empty()) return invalid_argument("no cache budget to replay " + args.trace_path + " with");
  for (const uint64_t budget : budgets) OUTCORE_RETURN_IF_ERROR(check_budget(trace, profile, budget));
  return budgets;
}

// Results of every (budget, policy) replay; the last column of each budget
// is OPT.
struct SimTable {
  std::vector<uint64_t> budgets;
  std::vector<std::string> policies;
  std::size_t columns = 0;
  std::vector<Expected<SimulationResult>> results;

  const SimulationResult& at(std::size_t b, std::size_t c) const { return *results[b * columns + c]; }
  const SimulationResult& opt(std::size_t b) const { return at(b, columns - 1); }
  double misses_vs_opt(std::size_t b, std::size_t c) const {
    const uint64_t opt_misses = opt(b).misses;
    return opt_misses ? static_cast<double>(at(b, c).misses) / static_cast<double>(opt_misses) : 1.0;
  }
};

Status run_simulations(const AccessTrace& trace, const TraceProfile& profile, SimTable& table) {
  table.columns = table.policies.size() + 1;
  table.results.assign(table.budgets.size() * table.columns, Status(StatusCode::kInternal, "not run"));
  tbb::parallel_for(std::size_t{0}, table.results.size(), [&](std::size_t job) {
    const uint64_t budget = table.budgets[job / table.columns];
    const std::size_t column = job % table.columns;
    table.results[job] = column < table.policies.size()
                             ? simulate_policy(trace, profile, table.policies[column], budget)
                             : simulate_opt(trace, profile, budget);
  });
  for (const auto& r : table.results) OUTCORE_RETURN_IF_ERROR(r.status());
  return Status::Ok();
}

void print_json(const CacheSimArgs& args, const AccessTrace& trace, const TraceProfile& profile,
                const SimTable& table) {
  JsonWriter j;
  j.begin_object();
  j.field("trace", args.trace_path).field("requests", uint64_t{trace.records.size()});
  j.field("distinct_bricks", profile.distinct_bricks).field("working_set_bytes", profile.working_set_bytes);
  j.field("recorded_policy", trace.info.policy).field("recorded_budget_bytes", trace.info.budget_bytes);
  j.key("results").begin_array();
  for (std::size_t b = 0; b < table.budgets.size(); ++b) {
    for (std::size_t c = 0; c < table.columns; ++c) {
      const SimulationResult& r = table.at(b, c);
      j.begin_object();
      j.field("policy", r.policy);
      if (!r.detail.empty()) j.field("rule", r.detail);
      j.field("budget_bytes", r.budget_bytes).field("requests", r.requests).field("hits", r.hits);
      j.field("misses", r.misses).field("miss_ratio", r.miss_ratio()).field("evictions", r.evictions);
      j.field("bytes_built", r.bytes_built).field("build_seconds", r.build_seconds);
      j.field("misses_vs_opt", table.misses_vs_opt(b, c));
      j.end_object();
    }
  }
  j.end_array().end_object();
  std::printf("%s\n", j.str().c_str());
}

void print_text(const CacheSimArgs& args, const AccessTrace& trace, const TraceProfile& profile,
                const SimTable& table) {
  std::printf("trace %s: %zu requests, %u distinct bricks, working set %.2f MiB", args.trace_path.c_str(),
              trace.records.size(), profile.distinct_bricks, mib(profile.working_set_bytes));
  if (!trace.info.policy.empty())
    std::printf(" (recorded with %s at %.2f MiB)", trace.info.policy.c_str(), mib(trace.info.budget_bytes));
  std::printf("\n%11s  %-7s %10s %10s %12s %12s %8s\n", "budget_MiB", "policy", "misses", "miss_ratio",
              "built_MiB", "build_s", "vs_opt");
  for (std::size_t b = 0; b < table.budgets.size(); ++b) {
    for (std::size_t c = 0; c < table.columns; ++c) {
      const SimulationResult& r = table.at(b, c);
      std::printf("%11.2f  %-7s %10llu %10.4f %12.2f %12.4f %8.3f\n", mib(r.budget_bytes), r.policy.c_str(),
                  static_cast<unsigned long long>(r.misses), r.miss_ratio(), mib(r.bytes_built),
                  r.build_seconds, table.misses_vs_opt(b, c));
    }
  }
  std::printf(
      "opt: Belady (furthest next use; exact for equal brick sizes, best of it and a size-aware\n"
      "rule otherwise). vs_opt: misses / OPT's misses.\n");
}

Status write_plot(const std::string& png_path, const AccessTrace& trace, const TraceProfile& profile,
                  const SimTable& table) {
  std::vector<PlotSeries> series(table.columns);
  for (std::size_t c = 0; c < table.columns; ++c) {
    series[c].name = c + 1 < table.columns ? table.policies[c] : "opt (Belady)";
    series[c].dashed = c + 1 == table.columns;
    for (std::size_t b = 0; b < table.budgets.size(); ++b) {
      series[c].x.push_back(mib(table.budgets[b]));
      series[c].y.push_back(table.at(b, c).miss_ratio());
    }
  }
  LinePlotConfig plot;
  plot.title = "Brick cache miss ratio by budget: " + std::to_string(trace.records.size()) + " requests, " +
               std::to_string(profile.distinct_bricks) + " bricks";
  plot.x_label = "cache budget (MiB, log scale)";
  plot.y_label = "miss ratio (builds / requests)";
  plot.log_x = table.budgets.size() > 1;
  OUTCORE_ASSIGN_OR_RETURN(const auto image, render_line_plot(series, plot));
  return write_png(png_path, image.width, image.height, image.pixels);
}

Status cache_sim(const CacheSimArgs& args) {
  if (!args.budget_mb.empty() && !args.budget_fractions.empty())
    return invalid_argument("give either --budget-mb or --budget-fractions, not both");
  SimTable table;
  OUTCORE_ASSIGN_OR_RETURN(table.policies, parse_policies(args.policy));
  OUTCORE_ASSIGN_OR_RETURN(const AccessTrace trace, read_access_trace(args.trace_path));
  if (trace.records.empty()) return invalid_argument(args.trace_path + " has no records");
  const TraceProfile profile = TraceProfile::of(trace);
  OUTCORE_ASSIGN_OR_RETURN(table.budgets, choose_budgets(args, trace, profile));
  OUTCORE_RETURN_IF_ERROR(run_simulations(trace, profile, table));
  if (args.json) {
    print_json(args, trace, profile, table);
  } else {
    print_text(args, trace, profile, table);
  }
  if (!args.png_path.empty()) OUTCORE_RETURN_IF_ERROR(write_plot(args.png_path, trace, profile, table));
  return Status::Ok();
}

int run_cache_sim(const CacheSimArgs& args) {
  const Status status = cache_sim(args);
  return status.ok() ? 0 : report_command_error("cache-sim", status.message());
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
