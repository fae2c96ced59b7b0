// Routing keys and the replica ring of cache-affinity routing (issue 30,
// docs/SCALING.md), the same as the Python client's (outcore/_routing.py):
// a ray's key is the cell of a flat-aware grid over the scene's box where it
// enters the box, placed on a 64-bit ring in Morton order; replicas are a
// few hashed points on the ring; keys go clockwise to the first replica
// within a bounded load. Same hash, grid and order in both clients, so that
// they send the same rays to the same replicas.
//
// Thread-safety: ReplicaRing is immutable once built; the functions are pure.
#pragma once

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/geometry/vec3.h"
#include "core/ray/ray_types.h"

namespace outcore::client {

inline constexpr uint32_t kRingVirtualNodes = 4;
inline constexpr uint32_t kRouteCells = 8;
inline constexpr double kRouteLoadFactor = 1.25;
inline constexpr uint64_t kMissBlockRays = 8192;
// Routing by brick: each replica's part within this x an even share of the
// triangles (a part must fit a replica's share of the cache), and more
// points a replica so that one joining takes close to 1/(N+1) of the bricks
// (outcore/_routing.py BRICK_LOAD_FACTOR, BRICK_VIRTUAL_NODES).
inline constexpr double kBrickLoadFactor = 1.01;
inline constexpr uint32_t kBrickVirtualNodes = 64;

// FNV-1a 64 over the bytes, then the SplitMix64 finaliser.
uint64_t ring_hash(std::string_view text);

// Cells along each axis: `cells` along the longest side, the others in
// proportion (at least 1).
std::array<uint32_t, 3> route_grid(const Vec3f& lo, const Vec3f& hi, uint32_t cells);

// Each ray's key: a position on the ring (see above); rays that miss the box
// get hashed positions by blocks of kMissBlockRays.
std::vector<uint64_t> route_keys(std::span<const Ray> rays, const Vec3f& lo, const Vec3f& hi,
                                 uint32_t cells = kRouteCells);

// A brick's place on the ring (routing by brick): the Morton code of its
// box's centre on a 128^3 grid over the scene's box (lo, hi), with the hash
// of "brick:ID" below it, so that no two bricks share a place.
uint64_t brick_ring_position(uint32_t brick, const Vec3f& brick_lo, const Vec3f& brick_hi, const Vec3f& lo,
                             const Vec3f& hi);

class ReplicaRing {
 public:
  explicit ReplicaRing(std::vector<std::string> replicas, uint32_t virtual_nodes = kRingVirtualNodes);
  const std::vector<std::string>& replicas() const { return replicas_; }  // sorted
  // Every replica once (indices into replicas()), clockwise from `position`.
  std::vector<uint32_t> walk(uint64_t position) const;
  // key -> replica index for keys with ray counts (largest first, each to
  // the first replica on its walk within load_factor x the average).
  std::map<uint64_t, uint32_t> assign(const std::map<uint64_t, uint64_t>& counts,
                                      double load_factor = kRouteLoadFactor) const;

 private:
  std::vector<std::string> replicas_;
  std::vector<std::pair<uint64_t, uint32_t>> points_;  // (hash, replica), sorted
};

}  // namespace outcore::client
