#include "tests/support/json_fields.h"

#include <gtest/gtest.h>

#include <cctype>
#include <cstdlib>

namespace outcore::testing {

uint64_t json_uint(const std::string& json, const std::string& key, int occurrence) {
  const std::string quoted = "\"" + key + "\"";
  std::size_t pos = std::string::npos;
  for (int k = 0, from = 0; k <= occurrence; ++k) {
    pos = json.find(quoted, from);
    if (pos == std::string::npos) {
      ADD_FAILURE() << "no " << quoted << " (#" << occurrence << ") in " << json;
      return 0;
    }
    from = static_cast<int>(pos + quoted.size());
  }
  pos = json.find(':', pos + quoted.size());
  if (pos == std::string::npos) {
    ADD_FAILURE() << "no value for " << quoted;
    return 0;
  }
  ++pos;
  while (pos < json.size() && json[pos] == ' ') ++pos;
  if (pos >= json.size() || !std::isdigit(static_cast<unsigned char>(json[pos]))) {
    ADD_FAILURE() << quoted << " is not an unsigned integer in " << json;
    return 0;
  }
  return std::strtoull(json.c_str() + pos, nullptr, 10);
}

}  // namespace outcore::testing
