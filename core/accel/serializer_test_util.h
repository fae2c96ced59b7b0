// Test helpers shared by the brick serialisers' tests (bvh, split-plane
// trees, grids): save a brick to bytes, wrap bytes as an unvouched payload,
// compare a built and a reloaded brick's answers bitwise, and load randomly
// corrupted payloads, tracing whatever loads.
//
// Thread-safety: test code; call from the test's thread.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "core/accel/accel_test_util.h"
#include "core/accel/brick_serializer.h"

namespace outcore::serializer_test {

inline std::string save(const BrickSerializer& serializer, const BrickAccel& accel) {
  std::ostringstream out;
  const Status saved = serializer.save(accel, out);
  EXPECT_TRUE(saved.ok()) << saved.to_string();
  return std::move(out).str();
}

// Bytes the caller does not vouch for: load() validates them.
inline SerializedBrick unowned(std::string_view bytes) {
  return SerializedBrick{bytes, nullptr, false};
}

// Closest hits and occlusion of `rays`, bitwise the same from both bricks;
// some rays must hit.
inline void expect_same_answers(const BrickAccel& built, const BrickAccel& loaded,
                                const std::vector<Ray>& rays, const std::string& what) {
  const auto ids = accel_test::all_ids(rays.size());
  std::vector<Hit> a(rays.size()), b(rays.size());
  built.intersect(ids, rays.data(), a.data());
  loaded.intersect(ids, rays.data(), b.data());
  EXPECT_GT(std::count_if(a.begin(), a.end(), [](const Hit& h) { return h.is_hit(); }), 0) << what;
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(Hit)), 0) << what;
  std::vector<uint8_t> oa(rays.size(), 0), ob(rays.size(), 0);
  built.occluded(ids, rays.data(), oa.data());
  loaded.occluded(ids, rays.data(), ob.data());
  EXPECT_EQ(oa, ob) << what;
}

struct FuzzOutcome {
  std::size_t refused = 0, loaded = 0;
};

// `rounds` copies of `payload` with one to four bits flipped (every other
// round within its first `front_bytes`, where headers and indices lie):
// each is refused with INVALID_ARGUMENT or loads and traces `rays` without
// a crash.
inline FuzzOutcome fuzz(const BrickSerializer& serializer, const std::string& payload,
                        uint32_t triangle_count, const std::vector<Ray>& rays, std::size_t front_bytes,
                        int rounds = 400) {
  std::mt19937_64 rng(11);
  FuzzOutcome outcome;
  const auto ids = accel_test::all_ids(rays.size());
  for (int round = 0; round < rounds; ++round) {
    std::string bytes = payload;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) {
      const std::size_t span = round % 2 == 0 ? std::min(bytes.size(), front_bytes) : bytes.size();
      bytes[rng() % span] ^= static_cast<char>(1u << (rng() % 8));
    }
    auto loaded = serializer.load(unowned(bytes), 0, triangle_count);
    if (!loaded.ok()) {
      EXPECT_EQ(loaded.status().code(), StatusCode::kInvalidArgument) << loaded.status().to_string();
      ++outcome.refused;
      continue;
    }
    ++outcome.loaded;
    std::vector<Hit> hits(rays.size());
    (*loaded)->intersect(ids, rays.data(), hits.data());
    std::vector<uint8_t> occluded(rays.size(), 0);
    (*loaded)->occluded(ids, rays.data(), occluded.data());
  }
  return outcome;
}

}  // namespace outcore::serializer_test
