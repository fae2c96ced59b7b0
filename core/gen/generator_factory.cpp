#include "core/gen/generator_factory.h"

namespace outcore {
// TEMPORARY until the generators land.
Expected<std::unique_ptr<TriangleSource>> make_generator(const std::string& spec) {
  return not_found("unknown generator in '" + spec + "'");
}
std::vector<std::string> generator_names() { return {}; }
}  // namespace outcore
