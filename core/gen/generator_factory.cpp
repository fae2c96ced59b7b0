#include "core/gen/generator_factory.h"

#include <array>

#include "core/gen/city_generator.h"
#include "core/gen/gen_spec.h"
#include "core/gen/sphere_generator.h"
#include "core/gen/stadium_generator.h"
#include "core/gen/terrain_generator.h"
#include "core/gen/torus_generator.h"

namespace outcore {

namespace {

using Create = Expected<std::unique_ptr<Generator>> (*)(const GenSpec&, const GeneratorOptions&);

template <class G>
Expected<std::unique_ptr<Generator>> create_as_generator(const GenSpec& spec,
                                                         const GeneratorOptions& options) {
  if constexpr (requires { G::create(spec, options); }) {
    OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<G> g, G::create(spec, options));
    return std::unique_ptr<Generator>(std::move(g));
  } else {
    OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<G> g, G::create(spec));
    return std::unique_ptr<Generator>(std::move(g));
  }
}

struct Entry {
  const char* name;
  Create create;
};

// The one registry of generators, sorted by name.
constexpr std::array<Entry, 5> kGenerators = {{
    {"city", &create_as_generator<CityGenerator>},
    {"sphere", &create_as_generator<SphereGenerator>},
    {"stadium", &create_as_generator<StadiumGenerator>},
    {"terrain", &create_as_generator<TerrainGenerator>},
    {"torus", &create_as_generator<TorusGenerator>},
}};

std::string known_names() {
  std::string s;
  for (const Entry& e : kGenerators) s += (s.empty() ? "" : ", ") + std::string(e.name);
  return s;
}

}  // namespace

Expected<std::unique_ptr<Generator>> make_typed_generator(const std::string& spec,
                                                          const GeneratorOptions& options) {
  if (!spec.starts_with("gen:")) {
    return invalid_argument("generator spec '" + spec + "' does not start with 'gen:'");
  }
  // Check the name before the parameters: an unknown generator is the more useful message.
  const std::string_view name = gen_spec_name(spec);
  const Entry* entry = nullptr;
  for (const Entry& e : kGenerators) {
    if (name == e.name) entry = &e;
  }
  if (entry == nullptr) {
    return not_found("unknown generator '" + std::string(name) + "' in '" + spec +
                     "' (known: " + known_names() + ")");
  }
  OUTCORE_ASSIGN_OR_RETURN(const GenSpec parsed, parse_gen_spec(spec));
  return entry->create(parsed, options);
}

Expected<std::unique_ptr<TriangleSource>> make_generator(const std::string& spec,
                                                         const GeneratorOptions& options) {
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<Generator> g, make_typed_generator(spec, options));
  return std::unique_ptr<TriangleSource>(std::move(g));
}

Expected<uint64_t> generator_triangle_count(const std::string& spec) {
  OUTCORE_ASSIGN_OR_RETURN(const std::unique_ptr<Generator> g, make_typed_generator(spec));
  return g->triangle_count();
}

std::vector<std::string> generator_names() {
  std::vector<std::string> names;
  for (const Entry& e : kGenerators) names.emplace_back(e.name);
  return names;
}

}  // namespace outcore
