#include "core/cache/access_trace.h"

#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

std::vector<AccessRecord> records(uint64_t first, uint64_t count) {
  std::vector<AccessRecord> out;
  for (uint64_t s = first; s < first + count; ++s) {
    AccessRecord r;
    r.seq = s;
    r.brick = static_cast<uint32_t>(s % 7);
    r.bytes = 1000 + s;
    r.reserved_bytes = 2000 + s;
    r.build_seconds = s % 3 == 0 ? 0.1 + 1e-9 * static_cast<double>(s) : 0.0;
    r.outcome = s % 3 == 0 ? AccessOutcome::kMiss : (s % 3 == 1 ? AccessOutcome::kHit : AccessOutcome::kWait);
    // Schedule hints on some records: one of three bricks, one empty.
    if (s % 5 == 2) {
      r.has_hint = true;
      r.hint = {static_cast<uint32_t>(s % 7), 6, 0};
    }
    if (s % 5 == 4) r.has_hint = true;
    out.push_back(r);
  }
  return out;
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream(path) << text;
}

TEST(AccessTraceTest, RoundTripsExactlyAndOrdersChunksBySeq) {
  testing::TempDir dir;
  const std::string path = dir.file("trace.csv");
  auto writer = AccessTraceWriter::create(path, "unit test");
  ASSERT_TRUE(writer.ok()) << writer.status().to_string();
  (*writer)->set_info("arc", 123456, "embree", 7);
  // Chunks handed over out of order, as threads may.
  (*writer)->append(records(10, 5));
  (*writer)->append(records(0, 10));
  (*writer)->append(records(15, 3));
  ASSERT_TRUE((*writer)->close().ok());
  EXPECT_EQ((*writer)->records_written(), 18u);

  auto trace = read_access_trace(path);
  ASSERT_TRUE(trace.ok()) << trace.status().to_string();
  EXPECT_EQ(trace->info.policy, "arc");
  EXPECT_EQ(trace->info.budget_bytes, 123456u);
  EXPECT_EQ(trace->info.builder, "embree");
  EXPECT_EQ(trace->info.bricks, 7u);
  EXPECT_EQ(trace->info.source, "unit test");
  const auto expected = records(0, 18);
  ASSERT_EQ(trace->records.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(trace->records[i].seq, expected[i].seq);
    EXPECT_EQ(trace->records[i].brick, expected[i].brick);
    EXPECT_EQ(trace->records[i].bytes, expected[i].bytes);
    EXPECT_EQ(trace->records[i].reserved_bytes, expected[i].reserved_bytes);
    EXPECT_EQ(trace->records[i].build_seconds, expected[i].build_seconds) << "must round-trip bit for bit";
    EXPECT_EQ(trace->records[i].outcome, expected[i].outcome);
    EXPECT_EQ(trace->records[i].has_hint, expected[i].has_hint) << i;
    EXPECT_EQ(trace->records[i].hint, expected[i].hint) << i;
  }
}

TEST(AccessTraceTest, AnEmptyTraceHasAHeader) {
  testing::TempDir dir;
  auto writer = AccessTraceWriter::create(dir.file("t.csv"), "");
  ASSERT_TRUE(writer.ok());
  ASSERT_TRUE((*writer)->close().ok());
  auto trace = read_access_trace(dir.file("t.csv"));
  ASSERT_TRUE(trace.ok()) << trace.status().to_string();
  EXPECT_TRUE(trace->records.empty());
}

TEST(AccessTraceTest, CannotCreateInAMissingDirectory) {
  auto writer = AccessTraceWriter::create("/nonexistent-dir/x/trace.csv", "");
  ASSERT_FALSE(writer.ok());
  EXPECT_NE(writer.status().message().find("/nonexistent-dir/x/trace.csv"), std::string::npos);
}

TEST(AccessTraceTest, MalformedFilesAreErrorsNamingFileAndLine) {
  testing::TempDir dir;
  const std::string header =
      "# outcore brick access trace, version 1\nseq,brick,bytes,reserved_bytes,build_seconds,outcome\n";
  struct Case {
    std::string text;
    std::string expected;  // part of the message
  };
  const std::vector<Case> cases = {
      {"", "empty file"},
      {"hello\n", ":1: not an outcore access trace"},
      {"# outcore brick access trace, version 4\n", ":1: access trace version '4' is not supported"},
      {"# outcore brick access trace, version 1\n0,1,2,3,0,hit\n", ":2: expected the column line"},
      {header + "0,1,100,100,0,hit\n1,1,100,100,0,maybe\n", ":4: outcome 'maybe'"},
      {header + "0,1,100,100,0\n", ":3: expected 6 fields, found 5"},
      {header + "0,x,100,100,0,hit\n", ":3: bad brick id 'x'"},
      {header + "0,1,100,100,-1,miss\n", ":3: bad build_seconds '-1'"},
      {header + "0,1,100,100,nan,miss\n", ":3: bad build_seconds 'nan'"},
      {header + "1,1,100,100,0,hit\n", ":3: seq 1 out of order (expected 0)"},
      {"# outcore brick access trace, version 1\n# bricks: 4\n"
       "seq,brick,bytes,reserved_bytes,build_seconds,outcome\n0,4,1,1,0,miss\n",
       ":4: brick 4 is beyond the trace's 4 bricks"},
      {header + "# hint: 1 y 2\n0,1,100,100,0,miss\n", ":3: bad brick id 'y' in a hint"},
      {"# outcore brick access trace, version 1\n# bricks: 4\n"
       "seq,brick,bytes,reserved_bytes,build_seconds,outcome\n# hint: 0 9\n0,1,1,1,0,miss\n",
       ":4: brick 9 in a hint is beyond the trace's 4 bricks"},
      {header + "# hint: 4000000000\n", ":3: brick 4000000000 in a hint is beyond"},
  };
  for (const Case& c : cases) {
    const std::string path = dir.file("bad.csv");
    write_text(path, c.text);
    auto trace = read_access_trace(path);
    ASSERT_FALSE(trace.ok()) << c.text;
    EXPECT_NE(trace.status().message().find(c.expected), std::string::npos)
        << "got: " << trace.status().message() << "\nwanted: " << c.expected;
    EXPECT_NE(trace.status().message().find("bad.csv"), std::string::npos) << trace.status().message();
  }
  auto missing = read_access_trace(dir.file("missing.csv"));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
