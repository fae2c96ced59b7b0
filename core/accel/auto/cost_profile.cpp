#include "core/accel/auto/cost_profile.h"

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <system_error>

#include <filesystem>

#include "core/util/atomic_file.h"
#include "core/util/parse_number.h"

namespace outcore {
namespace {

constexpr std::string_view kFirstLinePrefix = "# outcore cost profile, version ";
constexpr std::string_view kMachinePrefix = "# machine: ";

double dot(const std::array<double, kFeatureCount>& weights, const BrickFeatures& features) {
  const std::array<double, kFeatureCount> x = features.regressors();
  double sum = 0;
  for (std::size_t i = 0; i < kFeatureCount; ++i) sum += weights[i] * x[i];
  return sum;
}

std::vector<std::string> words_of(std::string_view line) {
  std::vector<std::string> words;
  std::istringstream in{std::string(line)};
  for (std::string word; in >> word;) words.push_back(word);
  return words;
}

// A "build" or "trace" line's five coefficients into `out`.
Status parse_coefficients(const std::vector<std::string>& words, const std::string& where,
                          std::array<double, kFeatureCount>& out) {
  if (words.size() != 2 + kFeatureCount) {
    return invalid_argument(where + ": '" + words[0] + "' needs a structure and " +
                            std::to_string(kFeatureCount) + " numbers, got " +
                            std::to_string(words.size() - 1) + " items");
  }
  for (std::size_t i = 0; i < kFeatureCount; ++i) {
    const std::string& text = words[2 + i];
    if (!parse_number(text, out[i]) || !std::isfinite(out[i]) || std::abs(out[i]) > 1e3) {
      return invalid_argument(where + ": coefficient " + kFeatureNames[i] + " of '" + words[1] +
                              "' must be a finite number of magnitude <= 1000, got '" + text + "'");
    }
  }
  return Status::Ok();
}

Status check_first_line(std::string_view line, const std::string& origin) {
  const std::string where = origin + ":1";
  if (line.substr(0, kFirstLinePrefix.size()) != kFirstLinePrefix) {
    return invalid_argument(where + ": not an outcore cost profile (the first line must be '" +
                            std::string(kFirstLinePrefix) + std::to_string(kCostProfileVersion) + "')");
  }
  int version = 0;
  if (!parse_number(std::string(line.substr(kFirstLinePrefix.size())), version)) {
    return invalid_argument(where + ": unreadable version in '" + std::string(line) + "'");
  }
  if (version != kCostProfileVersion) {
    return invalid_argument(where + ": cost profile version " + std::to_string(version) +
                            "; this outcore reads version " + std::to_string(kCostProfileVersion) +
                            " (run `outcore calibrate` again)");
  }
  return Status::Ok();
}

Expected<BrickFeatures> parse_sample(const std::vector<std::string>& words, const std::string& where) {
  BrickFeatures f;
  if (words.size() != 5) {
    return invalid_argument(where +
                            ": 'sample' needs triangles, density_spread, flatness and area_ratio, got " +
                            std::to_string(words.size() - 1) + " items");
  }
  const bool ok = parse_number(words[1], f.triangles) && parse_number(words[2], f.density_spread) &&
                  parse_number(words[3], f.flatness) && parse_number(words[4], f.area_ratio) &&
                  std::isfinite(f.density_spread) && f.density_spread >= 0 && f.density_spread <= 6.5 &&
                  f.flatness >= 0 && f.flatness <= 1 && std::isfinite(f.area_ratio) && f.area_ratio >= 0;
  if (!ok) {
    return invalid_argument(where +
                            ": sample needs a triangle count, a density_spread in [0, 6.5], a flatness "
                            "in [0, 1] and a finite area_ratio >= 0");
  }
  return f;
}

struct PendingCost {
  StructureCost cost;
  bool has_build = false, has_trace = false;
};

Status check_features_line(const std::vector<std::string>& words, const std::string& where) {
  bool same = words.size() == 1 + kFeatureCount;
  for (std::size_t i = 0; same && i < kFeatureCount; ++i) same = words[1 + i] == kFeatureNames[i];
  if (same) return Status::Ok();
  std::string expected;
  for (const char* name : kFeatureNames) expected += std::string(" ") + name;
  return invalid_argument(where + ": features must be listed as 'features" + expected + "'");
}

}  // namespace

double StructureCost::build_seconds(const BrickFeatures& features) const {
  return static_cast<double>(features.triangles) * std::exp(dot(build, features));
}

double StructureCost::trace_seconds_per_ray(const BrickFeatures& features) const {
  return std::exp(dot(trace, features));
}

const StructureCost* CostProfile::find(std::string_view structure) const {
  for (const StructureCost& cost : structures) {
    if (cost.structure == structure) return &cost;
  }
  return nullptr;
}

Expected<CostProfile> parse_cost_profile(std::string_view text, const std::string& origin) {
  CostProfile profile;
  profile.origin = origin;
  std::vector<PendingCost> pending;
  bool has_features = false;
  std::size_t line_number = 0;
  std::istringstream in{std::string(text)};
  for (std::string line; std::getline(in, line);) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::string where = origin + ":" + std::to_string(line_number);
    if (line_number == 1) {
      OUTCORE_RETURN_IF_ERROR(check_first_line(line, origin));
      continue;
    }
    if (line.rfind(kMachinePrefix, 0) == 0) profile.machine = line.substr(kMachinePrefix.size());
    const std::vector<std::string> words = words_of(line);
    if (words.empty() || words[0][0] == '#') continue;
    if (words[0] == "features") {
      OUTCORE_RETURN_IF_ERROR(check_features_line(words, where));
      has_features = true;
      continue;
    }
    if (words[0] == "sample") {
      OUTCORE_ASSIGN_OR_RETURN(BrickFeatures sample, parse_sample(words, where));
      profile.samples.push_back(sample);
      continue;
    }
    if (words[0] != "build" && words[0] != "trace") {
      return invalid_argument(where + ": unknown item '" + words[0] +
                              "' (known: features, build, trace, sample)");
    }
    if (!has_features) return invalid_argument(where + ": the 'features' line must come first");
    const bool is_build = words[0] == "build";
    std::array<double, kFeatureCount> coefficients{};
    OUTCORE_RETURN_IF_ERROR(parse_coefficients(words, where, coefficients));
    PendingCost* entry = nullptr;
    for (PendingCost& p : pending) {
      if (p.cost.structure == words[1]) entry = &p;
    }
    if (entry == nullptr) {
      entry = &pending.emplace_back();
      entry->cost.structure = words[1];
    }
    bool& seen = is_build ? entry->has_build : entry->has_trace;
    if (seen) return invalid_argument(where + ": a second '" + words[0] + "' line for '" + words[1] + "'");
    seen = true;
    (is_build ? entry->cost.build : entry->cost.trace) = coefficients;
  }
  if (line_number == 0) return invalid_argument(origin + ": empty, not an outcore cost profile");
  for (const PendingCost& p : pending) {
    if (!p.has_build || !p.has_trace) {
      return invalid_argument(origin + ": structure '" + p.cost.structure + "' has no '" +
                              (p.has_build ? "trace" : "build") + "' line");
    }
    profile.structures.push_back(p.cost);
  }
  if (profile.structures.empty()) return invalid_argument(origin + ": names no structure");
  return profile;
}

Expected<CostProfile> load_cost_profile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return not_found("cannot read cost profile " + path);
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return io_error("cannot read cost profile " + path);
  return parse_cost_profile(text.str(), path);
}

std::string format_cost_profile(const CostProfile& profile) {
  std::ostringstream out;
  out.precision(9);
  out << kFirstLinePrefix << kCostProfileVersion << "\n";
  if (!profile.machine.empty()) out << kMachinePrefix << profile.machine << "\n";
  out << "# build seconds = triangles * exp(build . x); trace seconds per ray = exp(trace . x)\n";
  out << "features";
  for (const char* name : kFeatureNames) out << " " << name;
  out << "\n";
  for (const StructureCost& cost : profile.structures) {
    for (const bool is_build : {true, false}) {
      out << (is_build ? "build " : "trace ") << cost.structure;
      for (const double c : is_build ? cost.build : cost.trace) out << " " << c;
      out << "\n";
    }
  }
  if (!profile.samples.empty())
    out << "# the measured bricks: triangles density_spread flatness area_ratio\n";
  for (const BrickFeatures& f : profile.samples) {
    out << "sample " << f.triangles << " " << f.density_spread << " " << f.flatness << " " << f.area_ratio
        << "\n";
  }
  return out.str();
}

Status save_cost_profile(const CostProfile& profile, const std::string& path) {
  const std::string text = format_cost_profile(profile);
  const std::string_view parts[] = {text};
  return write_file_atomically(path, parts);
}

std::string default_cost_profile_path() {
  if (const char* explicit_path = std::getenv("OUTCORE_COST_PROFILE"); explicit_path && *explicit_path)
    return explicit_path;
  std::string config;
  if (const char* xdg = std::getenv("XDG_CONFIG_HOME"); xdg && *xdg) {
    config = xdg;
  } else if (const char* home = std::getenv("HOME"); home && *home) {
    config = std::string(home) + "/.config";
  } else {
    return {};
  }
  return config + "/outcore/cost_profile.txt";
}

Expected<CostProfile> resolve_cost_profile(const std::string& path) {
  if (!path.empty()) return load_cost_profile(path);
  const std::string fallback = default_cost_profile_path();
  std::error_code ec;
  if (fallback.empty() || !std::filesystem::exists(fallback, ec)) return builtin_cost_profile();
  return load_cost_profile(fallback);
}

}  // namespace outcore
