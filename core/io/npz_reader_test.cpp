// The .npz reader: stored and deflated members read back byte for byte,
// ZIP64 extra fields honoured; truncated, corrupted and hostile archives are
// errors naming the archive (and the member), never a crash.
#include "core/io/npz_reader.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <random>
#include <string>
#include <vector>

namespace outcore {
namespace {

void put(std::string& out, uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out += static_cast<char>((value >> (8 * i)) & 0xff);
}

std::string deflated(const std::string& data) {
  z_stream zs{};
  EXPECT_EQ(deflateInit2(&zs, 6, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(deflateBound(&zs, data.size()), '\0');
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  zs.avail_in = static_cast<uInt>(data.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&zs, Z_FINISH), Z_STREAM_END);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}

struct Entry {
  std::string name, data;
  bool deflate = false;
  bool zip64 = false;  // sizes and offset in a ZIP64 extra field
};

// A ZIP archive as numpy.savez / savez_compressed write them.
std::string zip_of(const std::vector<Entry>& entries) {
  std::string out, directory;
  for (const Entry& e : entries) {
    const std::string body = e.deflate ? deflated(e.data) : e.data;
    const uint32_t crc =
        crc32(0, reinterpret_cast<const Bytef*>(e.data.data()), static_cast<uInt>(e.data.size()));
    const uint64_t offset = out.size();
    put(out, 0x04034b50, 4), put(out, 20, 2), put(out, 0, 2), put(out, e.deflate ? 8 : 0, 2), put(out, 0, 4);
    put(out, crc, 4), put(out, body.size(), 4), put(out, e.data.size(), 4);
    put(out, e.name.size(), 2), put(out, 0, 2);
    out += e.name + body;
    std::string extra;
    if (e.zip64)
      put(extra, 1, 2), put(extra, 24, 2), put(extra, e.data.size(), 8), put(extra, body.size(), 8),
          put(extra, offset, 8);
    put(directory, 0x02014b50, 4), put(directory, 45, 2), put(directory, 20, 2), put(directory, 0, 2);
    put(directory, e.deflate ? 8 : 0, 2), put(directory, 0, 4), put(directory, crc, 4);
    const uint64_t saturated = 0xffffffffu;
    put(directory, e.zip64 ? saturated : body.size(), 4),
        put(directory, e.zip64 ? saturated : e.data.size(), 4);
    put(directory, e.name.size(), 2), put(directory, extra.size(), 2), put(directory, 0, 2);
    put(directory, 0, 2), put(directory, 0, 2), put(directory, 0, 4),
        put(directory, e.zip64 ? saturated : offset, 4);
    directory += e.name + extra;
  }
  const uint64_t directory_offset = out.size();
  out += directory;
  put(out, 0x06054b50, 4), put(out, 0, 4), put(out, entries.size(), 2), put(out, entries.size(), 2);
  put(out, directory.size(), 4), put(out, directory_offset, 4), put(out, 0, 2);
  return out;
}

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

}  // namespace
}  // namespace outcore
