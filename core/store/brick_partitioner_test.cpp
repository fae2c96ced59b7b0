#include "core/store/brick_partitioner.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

// Small random triangles scattered through a box, with a few long slivers;
// primitive_id = position, so the permutation can be undone.
std::vector<PackedTriangle> random_triangles(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> position(-100.0f, 100.0f), offset(-1.0f, 1.0f);
  std::vector<PackedTriangle> out(n);
  for (size_t i = 0; i < n; ++i) {
    const Vec3f c(position(rng), position(rng), position(rng));
    const float size = i % 97 == 0 ? 40.0f : 1.0f;
    auto corner = [&] { return c + Vec3f(offset(rng), offset(rng), offset(rng)) * size; };
    out[i] = {{corner(), corner(), corner()}, 3, static_cast<uint32_t>(i)};
  }
  return out;
}

// The partition of `input` (as permuted in `output`) into `ranges` keeps every
// triangle exactly once, bit for bit; the ranges tile the array without gaps or
// overlaps; none is empty or larger than max; each range's bounds are exactly
// the bounds of its triangles.
void expect_valid_partition(const std::vector<PackedTriangle>& input,
                            const std::vector<PackedTriangle>& output, const std::vector<BrickRange>& ranges,
                            uint32_t max) {
  SCOPED_TRACE("max " + std::to_string(max));
  ASSERT_EQ(output.size(), input.size());
  std::vector<PackedTriangle> undone = output;
  std::sort(undone.begin(), undone.end(),
            [](const PackedTriangle& a, const PackedTriangle& b) { return a.primitive_id < b.primitive_id; });
  size_t moved = 0;
  for (size_t i = 0; i < input.size(); ++i) {
    ASSERT_EQ(undone[i].primitive_id, input[i].primitive_id) << "triangle lost or duplicated near " << i;
    moved += std::memcmp(&undone[i], &input[i], sizeof(PackedTriangle)) != 0;
  }
  EXPECT_EQ(moved, 0u) << "triangles altered by the partition";

  std::vector<BrickRange> sorted = ranges;
  std::sort(sorted.begin(), sorted.end(),
            [](const BrickRange& a, const BrickRange& b) { return a.begin < b.begin; });
  size_t next = 0;
  for (const BrickRange& r : sorted) {
    ASSERT_EQ(r.begin, next) << "gap or overlap";
    EXPECT_GE(r.count, 1u);
    EXPECT_LE(r.count, max);
    Aabb bounds;
    for (size_t i = r.begin; i < r.begin + r.count; ++i) bounds.extend(output[i].tri.bounds());
    EXPECT_EQ(r.bounds, bounds) << "range at " << r.begin;
    next = r.begin + r.count;
  }
  EXPECT_EQ(next, input.size());
  EXPECT_GE(ranges.size(), (input.size() + max - 1) / max);
}

std::vector<BrickRange> partition(std::vector<PackedTriangle>& triangles, uint32_t max) {
  BrickPartitionerConfig config;
  config.max_triangles = max;
  return partition_into_bricks(triangles, config);
}

TEST(BrickPartitioner, KeepsEveryTriangleInDisjointCoveringRangesNoneLargerThanMaxWithExactBounds) {
  const auto input = random_triangles(5000, 1);
  for (const uint32_t max : {1u, 2u, 7u, 64u, 1000u, 4999u, 5000u, 50000u}) {
    auto triangles = input;
    const auto ranges = partition(triangles, max);
    expect_valid_partition(input, triangles, ranges, max);
    if (max >= input.size()) {
      EXPECT_EQ(ranges.size(), 1u);
    }
  }
}

// Large enough for the parallel split and for split planes chosen from a sample;
// the bricks' bounds must still be exact.
TEST(BrickPartitioner, LargeInputUsesParallelSampledSplitsAndStaysExact) {
  const auto input = random_triangles(300'000, 2);
  // Large maxima make bricks of nodes whose parent chose its split from a
  // sample.
  for (const uint32_t max : {4096u, 50'000u, 200'000u}) {
    auto triangles = input;
    const auto ranges = partition(triangles, max);
    expect_valid_partition(input, triangles, ranges, max);
  }
}

TEST(BrickPartitioner, IdenticalTrianglesAreSplitInSequenceIntoBricksOfAtMostMax) {
  std::vector<PackedTriangle> input(10'000);
  for (uint32_t i = 0; i < input.size(); ++i) input[i] = {{{1, 2, 3}, {4, 5, 6}, {7, 9, 8}}, 0, i};
  auto triangles = input;
  const auto ranges = partition(triangles, 64);
  expect_valid_partition(input, triangles, ranges, 64);
  EXPECT_LE(ranges.size(), 2 * ((input.size() + 63) / 64));
}

TEST(BrickPartitioner, DifferentTrianglesSharingOneCentroidAreSplitToMax) {
  // Triangles rotated about a common centroid: the centroid bounds are a point
  // but the triangle bounds differ.
  std::vector<PackedTriangle> input(3000);
  for (uint32_t i = 0; i < input.size(); ++i) {
    const float a = 0.001f * static_cast<float>(i);
    const Vec3f p(std::cos(a), std::sin(a), 0.0f);
    input[i] = {{p, Vec3f(0, 0, 0) - p, Vec3f(0, 0, 0)}, 1, i};
  }
  auto triangles = input;
  const auto ranges = partition(triangles, 100);
  expect_valid_partition(input, triangles, ranges, 100);
}

TEST(BrickPartitioner, IsDeterministicAcrossRuns) {
  const auto input = random_triangles(300'000, 3);
  auto first = input, second = input;
  const auto ranges_first = partition(first, 1000);
  const auto ranges_second = partition(second, 1000);
  ASSERT_EQ(ranges_first.size(), ranges_second.size());
  for (size_t i = 0; i < ranges_first.size(); ++i) {
    EXPECT_EQ(ranges_first[i].begin, ranges_second[i].begin) << i;
    EXPECT_EQ(ranges_first[i].count, ranges_second[i].count) << i;
    EXPECT_EQ(ranges_first[i].bounds, ranges_second[i].bounds) << i;
  }
  EXPECT_EQ(std::memcmp(first.data(), second.data(), first.size() * sizeof(PackedTriangle)), 0);
}

TEST(BrickPartitioner, EmptyInputGivesNoBricksAndOneTriangleGivesOne) {
  std::vector<PackedTriangle> none;
  EXPECT_TRUE(partition(none, 10).empty());
  std::vector<PackedTriangle> one{{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, 0, 0}};
  const auto ranges = partition(one, 10);
  ASSERT_EQ(ranges.size(), 1u);
  EXPECT_EQ(ranges[0].begin, 0u);
  EXPECT_EQ(ranges[0].count, 1u);
  EXPECT_EQ(ranges[0].bounds, one[0].tri.bounds());
}

// Bricks come out near the target size on evenly spread geometry: not many
// more bricks than the minimum.
TEST(BrickPartitioner, UniformInputGivesBricksNearTheTargetSize) {
  std::vector<PackedTriangle> input;
  uint32_t id = 0;
  for (int z = 0; z < 200; ++z) {
    for (int x = 0; x < 200; ++x) {
      const Vec3f p(static_cast<float>(x), 0.0f, static_cast<float>(z));
      input.push_back({{p, p + Vec3f(1, 0, 0), p + Vec3f(0, 0, 1)}, 0, id++});
    }
  }
  auto triangles = input;
  const auto ranges = partition(triangles, 1000);
  expect_valid_partition(input, triangles, ranges, 1000);
  EXPECT_LE(ranges.size(), 2 * input.size() / 1000);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
