// Test helper for the OBJ and PLY readers: reads a file both ways, vertices
// held in memory and faces resolved out of core (vertex_spill.h) with the
// smallest buffers (many sort runs, merges of two runs at a time), and checks
// that both agree bit for bit: the same triangles, or the same error, and a
// second stream() identical to the first. Also checks that the out-of-core
// source leaves no temporary file behind.
//
// Thread-safety: test code; one thread.
#pragma once

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/gen/gen_test_util.h"
#include "core/io/triangle_source.h"
#include "tests/support/test_paths.h"

namespace outcore::testing {

using OpenFileFn = Expected<std::unique_ptr<TriangleSource>> (*)(const std::string&, const SourceOptions&);

// Forces the out-of-core path for any file with a vertex; buffers are then at
// their minimum.
inline constexpr uint64_t kSpillEveryVertex = 1;

inline bool same_bits(const std::vector<Triangle>& a, const std::vector<Triangle>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Triangle)) == 0);
}

inline Expected<std::vector<Triangle>> read_one_way(OpenFileFn open, const std::string& path,
                                                    const SourceOptions& options, bool restream) {
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<TriangleSource> source, open(path, options));
  auto first = read_all(*source);
  if (first.ok() && restream) {
    auto second = read_all(*source);
    EXPECT_TRUE(second.ok()) << second.status().to_string();
    if (second.ok()) {
      EXPECT_TRUE(same_bits(*first, *second)) << path << ": a second stream() differs";
    }
  }
  return first;
}

inline Expected<std::vector<Triangle>> read_both_ways(OpenFileFn open, const std::string& path) {
  auto in_memory = read_one_way(open, path, {}, /*restream=*/false);
  TempDir spill_dir;
  auto spilled = read_one_way(open, path, {kSpillEveryVertex, spill_dir.path()}, /*restream=*/true);
  EXPECT_TRUE(std::filesystem::is_empty(spill_dir.path())) << path << ": temporary files left behind";
  EXPECT_EQ(in_memory.ok(), spilled.ok()) << path << ": in memory " << in_memory.status().to_string()
                                          << ", out of core " << spilled.status().to_string();
  if (in_memory.ok() && spilled.ok()) {
    EXPECT_TRUE(same_bits(*in_memory, *spilled)) << path << ": out-of-core triangles differ";
  } else if (!in_memory.ok() && !spilled.ok()) {
    EXPECT_EQ(in_memory.status().code(), spilled.status().code()) << path;
    EXPECT_EQ(in_memory.status().message(), spilled.status().message()) << path;
  }
  return in_memory;
}

// Whether a source opened with this allowance streams from its spill files:
// they exist (in a directory under the given temp_dir) only then.
inline bool streams_out_of_core(OpenFileFn open, const std::string& path, uint64_t allowance) {
  TempDir spill_dir;
  auto source = open(path, {allowance, spill_dir.path()});
  EXPECT_TRUE(source.ok()) << source.status().to_string();
  if (!source.ok()) return false;
  bool spilled = false;
  CallbackSink sink([&](std::span<const Triangle>) {
    spilled = !std::filesystem::is_empty(spill_dir.path());
    return Status::Ok();
  });
  const Status status = (*source)->stream(sink);
  EXPECT_TRUE(status.ok()) << status.to_string();
  return spilled;
}

// The status of reading path out of core. After an error no spill file may
// remain, even while the source lives on.
inline Status read_out_of_core_status(OpenFileFn open, const std::string& path) {
  TempDir spill_dir;
  auto source = open(path, {kSpillEveryVertex, spill_dir.path()});
  if (!source.ok()) return source.status();
  const Status status = read_all(**source).status();
  if (!status.ok()) {
    EXPECT_TRUE(std::filesystem::is_empty(spill_dir.path())) << "temporary files left behind";
  }
  return status;
}

// A file whose vertices take vertex_bytes is read in memory with that much
// allowance (or none), and out of core with a byte less.
inline void expect_spills_only_beyond(OpenFileFn open, const std::string& path, uint64_t vertex_bytes) {
  EXPECT_FALSE(streams_out_of_core(open, path, 0));
  EXPECT_FALSE(streams_out_of_core(open, path, vertex_bytes));
  EXPECT_TRUE(streams_out_of_core(open, path, vertex_bytes - 1));
}

// Both ways, a failing sink stops the stream after its first batch and its
// status comes back unchanged.
inline void expect_sink_error_returned_unchanged(OpenFileFn open, const std::string& path) {
  TempDir spill_dir;
  for (const SourceOptions& options : {SourceOptions{}, SourceOptions{kSpillEveryVertex, spill_dir.path()}}) {
    SCOPED_TRACE(options.vertex_memory_bytes == 0 ? "in memory" : "out of core");
    auto source = open(path, options);
    ASSERT_TRUE(source.ok()) << source.status().to_string();
    int batches = 0;
    CallbackSink sink([&](std::span<const Triangle>) {
      ++batches;
      return resource_exhausted("sink is full");
    });
    const Status status = (*source)->stream(sink);
    EXPECT_EQ(batches, 1);
    EXPECT_EQ(status.code(), StatusCode::kResourceExhausted);
    EXPECT_EQ(status.message(), "sink is full");
  }
}

}  // namespace outcore::testing
