#include "core/io/bearer_token_file.h"

#include "core/io/npy.h"

namespace outcore {

Expected<std::string> read_bearer_token_file(const std::string& path) {
  OUTCORE_ASSIGN_OR_RETURN(std::string token, read_whole_file(path));
  while (!token.empty() &&
         (token.back() == '\n' || token.back() == '\r' || token.back() == ' ' || token.back() == '\t')) {
    token.pop_back();
  }
  if (token.empty()) return invalid_argument("token file " + path + " is empty");
  if (token.size() > kMaxBearerTokenBytes) {
    return invalid_argument("token file " + path + " holds " + std::to_string(token.size()) +
                            " bytes; at most " + std::to_string(kMaxBearerTokenBytes) + " are allowed");
  }
  for (std::size_t i = 0; i < token.size(); ++i) {
    const auto ch = static_cast<unsigned char>(token[i]);
    if (ch <= 0x20 || ch == 0x7f) {
      return invalid_argument("token file " + path + " has a space or control character at byte " +
                              std::to_string(i) + " (a token is one word of visible characters)");
    }
  }
  return token;
}

bool tokens_equal(std::string_view given, std::string_view expected) {
  // The length is not secret (tokens are of a fixed length in practice);
  // the bytes are compared without an early exit.
  if (given.size() != expected.size()) return false;
  unsigned char difference = 0;
  for (std::size_t i = 0; i < given.size(); ++i) {
    difference |= static_cast<unsigned char>(given[i] ^ expected[i]);
  }
  return difference == 0;
}

}  // namespace outcore
