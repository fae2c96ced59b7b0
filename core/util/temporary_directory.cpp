#include "core/util/temporary_directory.h"

#include <stdlib.h>

#include <cstdlib>
#include <filesystem>
#include <system_error>

namespace outcore {

TemporaryDirectory::~TemporaryDirectory() {
  remove();
}

Status TemporaryDirectory::create(const std::string& prefix) {
  remove();
  std::string pattern = prefix + "XXXXXX";
  if (mkdtemp(pattern.data()) == nullptr)
    return io_error_from_errno("cannot create a temporary directory " + pattern);
  path_ = pattern;
  return Status::Ok();
}

Status TemporaryDirectory::create_beside(const std::string& output) {
  return create(output + ".partial-");
}

void TemporaryDirectory::remove() {
  if (path_.empty()) return;
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
  path_.clear();
}

std::string default_temp_directory() {
  const char* dir = std::getenv("TMPDIR");
  return dir != nullptr && *dir != '\0' ? std::string(dir) : std::string("/tmp");
}

}  // namespace outcore
