// Paths the tests need: the repository's test models (tests/data/models) and the built `outcore` binary.
//
// Thread-safety: pure functions.
#pragma once

#include <cstddef>
#include <string>

namespace outcore::testing {

inline std::string model_path(const std::string& name) {
  return std::string(OUTCORE_MODELS_DIR) + "/" + name;
}
inline std::string outcore_binary() {
  return OUTCORE_BINARY;
}

// A fresh empty directory under the system temp dir, removed by the destructor.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// How many times `part` occurs in `text` (overlapping occurrences counted).
inline std::size_t count_of(const std::string& text, const std::string& part) {
  std::size_t n = 0;
  for (auto pos = text.find(part); pos != std::string::npos; pos = text.find(part, pos + 1)) ++n;
  return n;
}

// Writes text to a file (test fixtures), aborting the test on failure.
void write_text_file(const std::string& path, const std::string& text);
// A whole file's bytes (empty when it cannot be read).
std::string read_file_bytes(const std::string& path);

}  // namespace outcore::testing
