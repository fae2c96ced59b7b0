// Transparent huge pages for the process's heap, on request. Brick trees
// are read in random order across hundreds of megabytes; with 4 KiB pages
// many brick visits miss the TLB. Where the kernel gives huge pages only to
// memory that asks for them (THP "madvise", Debian's default), glibc asks for
// its heap when started with GLIBC_TUNABLES=glibc.malloc.hugetlb=1, and it
// reads tunables only at start, so with OUTCORE_HUGE_PAGES=1 the `outcore`
// command re-executes itself once with that tunable added. Off by default:
// warm batches of the large scenes take 0.88-0.96x the time, but every
// brick build then faults in and zeroes 2 MiB pages, and cold batches took
// ~1.2x the time (docs/BENCHMARKS.md, issue 23), which an out-of-core run
// pays on every rebuild. A GLIBC_TUNABLES that already names the tunable is
// left as the user set it.
//
// Thread-safety: call reexec_with_huge_page_heap() first thing in main,
// before any thread exists; the decision functions are pure.
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace outcore {

inline constexpr std::string_view kHugePageTunable = "glibc.malloc.hugetlb=1";

// The GLIBC_TUNABLES value to re-execute with, or nothing when the process
// should run as it is: not asked for (request other than "1"), already
// re-executed (reexecuted), or the tunable already set (in any value).
std::optional<std::string> huge_page_tunables(const char* current_tunables, const char* request,
                                              bool reexecuted);

// Whether the kernel's THP mode (the content of
// /sys/kernel/mm/transparent_hugepage/enabled, the bracketed word chosen)
// gives huge pages to memory that asks: "madvise" only ("always" gives them
// anyway, "never" or an unknown file none).
bool huge_pages_on_request(std::string_view thp_enabled);

// Re-executes /proc/self/exe with argv and the tunable added when
// huge_page_tunables says so and the kernel gives huge pages on request (the
// mode file is read only then); returns (and the process goes on as it is)
// otherwise, or when the re-execution fails.
void reexec_with_huge_page_heap(char** argv);

}  // namespace outcore
