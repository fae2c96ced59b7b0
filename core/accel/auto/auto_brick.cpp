#include "core/accel/auto/auto_brick.h"

#include <algorithm>
#include <sstream>

#include "core/accel/auto/auto_brick_serializer.h"

namespace outcore {
namespace {

bool allowed_candidate(const std::string& name) {
  return std::find(std::begin(kDefaultAutoCandidates), std::end(kDefaultAutoCandidates), name) !=
         std::end(kDefaultAutoCandidates);
}

std::string allowed_list() {
  std::string out;
  for (const char* name : kDefaultAutoCandidates) out += (out.empty() ? "" : ", ") + std::string(name);
  return out;
}

Expected<std::vector<std::string>> parse_candidates(const std::string& value) {
  std::vector<std::string> names;
  std::istringstream in(value);
  for (std::string name; std::getline(in, name, ',');) {
    if (!allowed_candidate(name)) {
      return invalid_argument("brick accel auto: candidate '" + name + "' is not one of " + allowed_list() +
                              " (embree and reference use another triangle test)");
    }
    if (std::find(names.begin(), names.end(), name) != names.end())
      return invalid_argument("brick accel auto: candidate '" + name + "' listed twice");
    names.push_back(name);
  }
  if (names.empty()) return invalid_argument("brick accel auto: option candidates names no structure");
  return names;
}

// The probe bricks of dominated_candidates().
std::vector<BrickFeatures> probe_bricks() {
  std::vector<BrickFeatures> probes;
  for (uint32_t triangles = 256; triangles <= (uint32_t{1} << 18); triangles *= 4) {
    for (const double spread : {0.0, 2.0, 4.0, 6.0}) {
      for (const double flatness : {0.0, 0.5, 1.0}) {
        for (const double area : {0.5, 1.0, 4.0}) {
          BrickFeatures f;
          f.triangles = triangles, f.density_spread = spread, f.flatness = flatness, f.area_ratio = area;
          probes.push_back(f);
        }
      }
    }
  }
  return probes;
}

}  // namespace

std::vector<std::string> never_chosen_candidates(const std::vector<std::string>& names,
                                                 const CostProfile& profile) {
  std::vector<const StructureCost*> costs;
  for (const std::string& name : names) costs.push_back(profile.find(name));
  std::vector<bool> chosen(names.size(), false);
  for (const BrickFeatures& f : profile.samples.empty() ? probe_bricks() : profile.samples) {
    std::vector<double> build(names.size()), trace(names.size());
    for (std::size_t c = 0; c < names.size(); ++c) {
      if (costs[c] == nullptr) continue;
      build[c] = costs[c]->build_seconds(f);
      trace[c] = costs[c]->trace_seconds_per_ray(f);
    }
    for (double rays = 0; rays < 1e13; rays = rays == 0 ? 1 : rays * 2) {
      std::size_t best = names.size();
      for (std::size_t c = 0; c < names.size(); ++c) {
        if (costs[c] == nullptr) continue;
        if (best == names.size() || build[c] + rays * trace[c] < build[best] + rays * trace[best]) best = c;
      }
      if (best < names.size()) chosen[best] = true;
    }
  }
  std::vector<std::string> never;
  for (std::size_t c = 0; c < names.size(); ++c) {
    if (!chosen[c]) never.push_back(names[c]);
  }
  return never;
}

Expected<std::unique_ptr<AutoBrickBuilder>> AutoBrickBuilder::create(const Config& config) {
  std::unique_ptr<AutoBrickBuilder> builder(new AutoBrickBuilder());
  OUTCORE_ASSIGN_OR_RETURN(builder->profile_, resolve_cost_profile(config.profile_path));
  if (config.candidates.empty()) {
    // The defaults the profile measured (calibrate --structures may have
    // measured fewer); named candidates must all be in it.
    for (const char* name : kDefaultAutoCandidates) {
      if (builder->profile_.find(name) != nullptr) builder->candidate_names_.emplace_back(name);
    }
    if (builder->candidate_names_.empty()) {
      return invalid_argument("brick accel auto: cost profile " + builder->profile_.origin +
                              " has costs for none of " + allowed_list());
    }
  } else {
    builder->candidate_names_ = config.candidates;
  }
  for (const std::string& name : builder->candidate_names_) {
    if (builder->profile_.find(name) == nullptr) {
      return invalid_argument("brick accel auto: cost profile " + builder->profile_.origin +
                              " has no costs for candidate '" + name +
                              "' (run `outcore calibrate` or drop it from candidates)");
    }
  }
  builder->dropped_names_ = never_chosen_candidates(builder->candidate_names_, builder->profile_);
  std::erase_if(builder->candidate_names_, [&](const std::string& name) {
    return std::find(builder->dropped_names_.begin(), builder->dropped_names_.end(), name) !=
           builder->dropped_names_.end();
  });
  for (const std::string& name : builder->candidate_names_) {
    OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<BrickBuilder> made,
                             make_brick_builder(name, config.candidate_options));
    const StructureCost* cost = builder->profile_.find(name);
    builder->hit_rounding_scale_ = std::max(builder->hit_rounding_scale_, made->hit_rounding_scale());
    builder->costs_.push_back(*cost);
    builder->builders_.push_back(std::move(made));
  }
  builder->serializer_ = make_auto_brick_serializer(*builder);
  return builder;
}

StructureChoice AutoBrickBuilder::choose(const BrickFeatures& features, uint64_t rays) const {
  StructureChoice choice;
  choice.predicted_seconds.resize(costs_.size());
  for (std::size_t c = 0; c < costs_.size(); ++c) {
    choice.predicted_seconds[c] = costs_[c].build_seconds(features) +
                                  static_cast<double>(rays) * costs_[c].trace_seconds_per_ray(features);
    if (choice.predicted_seconds[c] < choice.predicted_seconds[choice.candidate])
      choice.candidate = static_cast<uint32_t>(c);
  }
  return choice;
}

Expected<std::unique_ptr<BrickAccel>> AutoBrickBuilder::build(BrickData&& brick) const {
  return build_for(std::move(brick), BuildDemand{});
}

Expected<std::unique_ptr<BrickAccel>> AutoBrickBuilder::build_for(BrickData&& brick,
                                                                  const BuildDemand& demand) const {
  const BrickFeatures features = measure_brick_features(brick.triangles);
  const uint32_t candidate = choose(features, demand.rays_expected).candidate;
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<BrickAccel> inner, builders_[candidate]->build(std::move(brick)));
  return std::unique_ptr<BrickAccel>(new AutoBrickAccel(std::move(inner), candidate, features));
}

bool AutoBrickBuilder::worth_rebuilding(const BrickAccel& accel, const BuildDemand& demand) const {
  const auto* built = dynamic_cast<const AutoBrickAccel*>(&accel);
  if (built == nullptr || demand.rays_expected == 0) return false;
  const StructureChoice best = choose(built->features(), demand.rays_expected);
  if (best.candidate == built->candidate()) return false;
  const double rays = static_cast<double>(demand.rays_expected);
  const double saved_per_ray = costs_[built->candidate()].trace_seconds_per_ray(built->features()) -
                               costs_[best.candidate].trace_seconds_per_ray(built->features());
  return rays * saved_per_ray > kRebuildMargin * costs_[best.candidate].build_seconds(built->features());
}

std::string_view AutoBrickBuilder::structure_of(const BrickAccel& accel) const {
  const auto* built = dynamic_cast<const AutoBrickAccel*>(&accel);
  return built != nullptr ? std::string_view(candidate_names_[built->candidate()]) : std::string_view(name_);
}

uint32_t AutoBrickBuilder::resident_set_max_bricks() const {
  uint32_t most = 0;
  for (const auto& builder : builders_) most = std::max(most, builder->resident_set_max_bricks());
  return most;
}

Expected<std::unique_ptr<ResidentBrickSet>> AutoBrickBuilder::make_resident_set(
    std::span<const BrickAccel* const> bricks) const {
  if (bricks.empty()) return std::unique_ptr<ResidentBrickSet>();
  std::vector<const BrickAccel*> inner(bricks.size());
  uint32_t candidate = 0;
  for (std::size_t b = 0; b < bricks.size(); ++b) {
    const auto* built = dynamic_cast<const AutoBrickAccel*>(bricks[b]);
    if (built == nullptr) return std::unique_ptr<ResidentBrickSet>();
    if (b == 0) candidate = built->candidate();
    if (built->candidate() != candidate) return std::unique_ptr<ResidentBrickSet>();
    inner[b] = &built->inner();
  }
  if (bricks.size() > builders_[candidate]->resident_set_max_bricks())
    return std::unique_ptr<ResidentBrickSet>();
  return builders_[candidate]->make_resident_set(inner);
}

uint64_t AutoBrickBuilder::reserve_bytes(uint32_t triangle_count) const {
  uint64_t most = 0;
  for (const auto& builder : builders_) most = std::max(most, builder->reserve_bytes(triangle_count));
  return most + sizeof(AutoBrickAccel);
}

Expected<std::unique_ptr<BrickBuilder>> make_auto_builder(const BrickAccelOptions& options) {
  AutoBrickBuilder::Config config;
  for (const auto& [key, value] : options) {
    if (key == "candidates") {
      OUTCORE_ASSIGN_OR_RETURN(config.candidates, parse_candidates(value));
    } else if (key == "triangle_test") {
      config.candidate_options[key] = value;
    } else if (key == "profile") {
      if (value.empty()) return invalid_argument("brick accel auto: option profile needs a file name");
      config.profile_path = value;
    } else {
      return invalid_argument("brick accel auto: unknown option '" + key +
                              "' (known: candidates, triangle_test, profile)");
    }
  }
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<AutoBrickBuilder> builder, AutoBrickBuilder::create(config));
  return std::unique_ptr<BrickBuilder>(std::move(builder));
}

}  // namespace outcore
