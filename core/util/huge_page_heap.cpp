#include "core/util/huge_page_heap.h"

#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

namespace outcore {
namespace {

// Set in the re-executed process so that it never re-executes again.
constexpr const char* kReexecMarker = "OUTCORE_HUGE_PAGES_REEXEC";

std::string read_thp_mode() {
  std::ifstream file("/sys/kernel/mm/transparent_hugepage/enabled");
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

}  // namespace

std::optional<std::string> huge_page_tunables(const char* current_tunables, const char* request,
                                              bool reexecuted) {
  if (reexecuted) return std::nullopt;
  if (request == nullptr || std::string_view(request) != "1") return std::nullopt;
  const std::string_view current = current_tunables != nullptr ? current_tunables : "";
  if (current.find("glibc.malloc.hugetlb=") != std::string_view::npos) return std::nullopt;
  std::string tunables(current);
  if (!tunables.empty()) tunables += ':';
  tunables += kHugePageTunable;
  return tunables;
}

bool huge_pages_on_request(std::string_view thp_enabled) {
  return thp_enabled.find("[madvise]") != std::string_view::npos;
}

void reexec_with_huge_page_heap(char** argv) {
  const char* current = std::getenv("GLIBC_TUNABLES");
  const std::optional<std::string> tunables =
      huge_page_tunables(current, std::getenv("OUTCORE_HUGE_PAGES"), std::getenv(kReexecMarker) != nullptr);
  if (!tunables || !huge_pages_on_request(read_thp_mode())) return;
  const std::optional<std::string> original =
      current != nullptr ? std::optional<std::string>(current) : std::nullopt;
  if (setenv("GLIBC_TUNABLES", tunables->c_str(), 1) == 0 && setenv(kReexecMarker, "1", 1) == 0) {
    execv("/proc/self/exe", argv);
  }
  // Still here: exec failed (no /proc, say); run as we are, environment as it was.
  unsetenv(kReexecMarker);
  if (original) {
    setenv("GLIBC_TUNABLES", original->c_str(), 1);
  } else {
    unsetenv("GLIBC_TUNABLES");
  }
}

}  // namespace outcore
