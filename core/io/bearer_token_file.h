// The bearer token a server requires and a client sends (serve / query
// --auth-token-file, metadata "authorization: Bearer TOKEN"), read from a
// file so that it never appears in a process list or a shell history.
//
// Thread-safety: pure functions.
#pragma once

#include <string>
#include <string_view>

#include "core/util/status.h"

namespace outcore {

// Tokens longer than this are refused (an HTTP/2 header must stay small).
inline constexpr std::size_t kMaxBearerTokenBytes = 4096;

// The token in `path`: its text without trailing newlines and spaces.
// INVALID_ARGUMENT naming the file when it is empty, too long, or holds
// spaces or control characters inside the token (a header value must not);
// NOT_FOUND when it does not exist, IO_ERROR when it cannot be read.
Expected<std::string> read_bearer_token_file(const std::string& path);

// Compares in time independent of where the two first differ, so that the
// server's answers do not reveal how much of a guessed token was right.
bool tokens_equal(std::string_view given, std::string_view expected);

}  // namespace outcore
