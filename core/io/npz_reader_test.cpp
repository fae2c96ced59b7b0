// The .npz reader: stored and deflated members read back byte for byte,
// ZIP64 extra fields honoured; truncated, corrupted and hostile archives are
// errors naming the archive (and the member), never a crash.
#include "core/io/npz_reader.h"

#include <gtest/gtest.h>

#include <random>
#include <string>
#include <vector>

#include "core/io/npz_test_util.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

using testing::Entry;
using testing::zip_of;

std::string payload(std::size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::string s(n, '\0');
  for (char& c : s) c = static_cast<char>(rng() % 7);  // compressible
  return s;
}

TEST(NpzReader, StoredDeflatedAndZip64MembersReadBackExactly) {
  const std::vector<Entry> entries = {{"a.npy", payload(1000, 1), false, false},
                                      {"b.npy", payload(70000, 2), true, false},
                                      {"c.npy", payload(300, 3), false, true},
                                      {"notes", "plain", true, true}};
  const auto members = decode_npz(zip_of(entries), "x.npz");
  ASSERT_TRUE(members.ok()) << members.status().to_string();
  ASSERT_EQ(members->size(), 4u);
  EXPECT_EQ(members->at("a"), entries[0].data);
  EXPECT_EQ(members->at("b"), entries[1].data);
  EXPECT_EQ(members->at("c"), entries[2].data);
  EXPECT_EQ(members->at("notes"), "plain");
}

TEST(NpzReader, BrokenArchivesAreErrorsNamingThem) {
  const std::string good = zip_of({{"a.npy", payload(5000, 4), true, false}, {"b.npy", payload(900, 5)}});
  const auto expect_error = [](const std::string& bytes, const std::string& words) {
    const auto got = decode_npz(bytes, "scene.npz");
    ASSERT_FALSE(got.ok()) << words;
    EXPECT_NE(got.status().message().find("scene.npz"), std::string::npos) << got.status().to_string();
    EXPECT_NE(got.status().message().find(words), std::string::npos) << got.status().to_string();
  };
  expect_error("", "too short");
  expect_error(std::string(100, 'x'), "no end of central directory");
  expect_error(good.substr(0, good.size() / 2), "no end of central directory");
  std::string flipped = good;
  flipped[60] ^= 0x55;  // inside a's deflated data
  const auto corrupt = decode_npz(flipped, "scene.npz");
  ASSERT_FALSE(corrupt.ok());
  EXPECT_NE(corrupt.status().message().find("member a.npy"), std::string::npos)
      << corrupt.status().to_string();
  std::string twice = zip_of({{"a.npy", "1"}, {"a.npy", "2"}});
  expect_error(twice, "appears twice");
}

TEST(NpzReader, HostileBytesNeverCrash) {
  const std::string good =
      zip_of({{"a.npy", payload(3000, 6), true, false}, {"b.npy", payload(500, 7), false, true}});
  std::mt19937 rng(11);
  int failures = 0;
  for (int trial = 0; trial < 1500; ++trial) {
    std::string bytes = good;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) bytes[rng() % bytes.size()] = static_cast<char>(rng());
    if (trial % 3 == 0) bytes.resize(rng() % bytes.size());
    failures += !decode_npz(bytes, "fuzz.npz").ok();
  }
  EXPECT_GT(failures, 500);  // most damage is caught (the rest hit bytes nothing reads)
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
