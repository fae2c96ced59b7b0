// Splits an in-memory set of triangles into spatially compact bricks of at most
// `max_triangles` each (object partition: every triangle in exactly one brick)
// with a binned SAH whose cost charges each side of a split a fixed overhead per
// brick it will need, so that bricks come out near the target size unless
// isolating a few large triangles pays for itself (the "teapot in a stadium").
//
// Thread-safety: pure function of its arguments; internally parallel (TBB).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/geometry/triangle.h"

namespace outcore {

struct BrickPartitionerConfig {
  // Largest brick; a node with more triangles is always split.
  uint32_t max_triangles = 32768;
  // SAH bins per axis.
  int bins = 32;
  // Overhead of one brick, in triangles' worth of cost; 0 means max_triangles/2.
  double brick_overhead_triangles = 0.0;
};

struct BrickRange {
  std::size_t begin = 0;  // into the permuted triangle array
  std::size_t count = 0;
  Aabb bounds;  // of the triangles (not their centroids)
};

// Permutes `triangles` so each brick is a contiguous range and returns the
// ranges in a deterministic depth-first order (spatial neighbours adjacent).
std::vector<BrickRange> partition_into_bricks(std::span<PackedTriangle> triangles,
                                              const BrickPartitionerConfig& config);

}  // namespace outcore
