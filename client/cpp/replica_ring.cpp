#include "client/cpp/replica_ring.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace outcore::client {

namespace {

uint64_t spread_bits(uint64_t v) {
  v &= 0x1FFFFF;
  v = (v | v << 32) & 0x1F00000000FFFFull;
  v = (v | v << 16) & 0x1F0000FF0000FFull;
  v = (v | v << 8) & 0x100F00F00F00F00Full;
  v = (v | v << 4) & 0x10C30C30C30C30C3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

// The first non-NaN of max/min over the three axes (NaN: every axis NaN).
double nan_max(const std::array<double, 3>& v) {
  double best = std::numeric_limits<double>::quiet_NaN();
  for (const double x : v)
    if (!std::isnan(x) && (std::isnan(best) || x > best)) best = x;
  return best;
}
double nan_min(const std::array<double, 3>& v) {
  double best = std::numeric_limits<double>::quiet_NaN();
  for (const double x : v)
    if (!std::isnan(x) && (std::isnan(best) || x < best)) best = x;
  return best;
}

}  // namespace

uint64_t ring_hash(std::string_view text) {
  uint64_t h = 0xCBF29CE484222325ull;
  for (const char c : text) h = (h ^ static_cast<unsigned char>(c)) * 0x100000001B3ull;
  h = (h ^ (h >> 30)) * 0xBF58476D1CE4E5B9ull;
  h = (h ^ (h >> 27)) * 0x94D049BB133111EBull;
  return h ^ (h >> 31);
}

uint64_t brick_ring_position(uint32_t brick, const Vec3f& brick_lo, const Vec3f& brick_hi, const Vec3f& lo,
                             const Vec3f& hi) {
  const double centre[3] = {(double(brick_lo.x) + brick_hi.x) / 2, (double(brick_lo.y) + brick_hi.y) / 2,
                            (double(brick_lo.z) + brick_hi.z) / 2};
  const double low[3] = {lo.x, lo.y, lo.z};
  const double high[3] = {hi.x, hi.y, hi.z};
  uint64_t code = 0;
  for (int a = 0; a < 3; ++a) {
    const double extent = high[a] > low[a] ? high[a] - low[a] : 1.0;
    const double cell = std::clamp(std::floor((centre[a] - low[a]) / extent * 128), 0.0, 127.0);
    code |= spread_bits(static_cast<uint64_t>(cell)) << a;
  }
  return code << 43 | ring_hash("brick:" + std::to_string(brick)) >> 21;
}

std::array<uint32_t, 3> route_grid(const Vec3f& lo, const Vec3f& hi, uint32_t cells) {
  const double extent[3] = {std::max(0.0, double(hi.x) - lo.x), std::max(0.0, double(hi.y) - lo.y),
                            std::max(0.0, double(hi.z) - lo.z)};
  double longest = std::max({extent[0], extent[1], extent[2]});
  if (!(longest > 0)) longest = 1;
  std::array<uint32_t, 3> dims{};
  for (int a = 0; a < 3; ++a) {
    dims[a] = static_cast<uint32_t>(std::max(1.0, std::floor(cells * extent[a] / longest + 0.5)));
  }
  return dims;
}

std::vector<uint64_t> route_keys(std::span<const Ray> rays, const Vec3f& lo, const Vec3f& hi,
                                 uint32_t cells) {
  const std::array<uint32_t, 3> dims = route_grid(lo, hi, cells);
  const uint32_t most = std::max({dims[0], dims[1], dims[2]});
  const uint32_t bits = 3 * (most > 1 ? std::max(1u, static_cast<uint32_t>(std::ceil(std::log2(most)))) : 1u);
  const double low[3] = {lo.x, lo.y, lo.z};
  const double high[3] = {hi.x, hi.y, hi.z};
  std::vector<uint64_t> keys(rays.size());
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    const double o[3] = {ray.origin.x, ray.origin.y, ray.origin.z};
    const double d[3] = {ray.direction.x, ray.direction.y, ray.direction.z};
    std::array<double, 3> near{}, far{};
    for (int a = 0; a < 3; ++a) {
      const double t0 = (low[a] - o[a]) / d[a];
      const double t1 = (high[a] - o[a]) / d[a];
      near[a] = std::fmin(t0, t1);
      far[a] = std::fmax(t0, t1);
    }
    const double t_enter = std::fmax(nan_max(near), double(ray.tnear));
    const double t_exit = std::fmin(nan_min(far), double(ray.tfar));
    if (!(std::isfinite(t_enter) && t_enter <= t_exit)) {
      keys[i] = ring_hash("miss:" + std::to_string(i / kMissBlockRays));
      continue;
    }
    uint64_t code = 0;
    for (int a = 0; a < 3; ++a) {
      const double extent = high[a] > low[a] ? high[a] - low[a] : 1.0;
      double cell = std::floor((o[a] + t_enter * d[a] - low[a]) / extent * dims[a]);
      if (std::isnan(cell)) cell = 0;
      cell = std::clamp(cell, 0.0, double(dims[a] - 1));
      code |= spread_bits(static_cast<uint64_t>(cell)) << a;
    }
    keys[i] = (code << (64 - bits)) + (uint64_t{1} << (63 - bits));
  }
  return keys;
}

ReplicaRing::ReplicaRing(std::vector<std::string> replicas, uint32_t virtual_nodes)
    : replicas_(std::move(replicas)) {
  std::sort(replicas_.begin(), replicas_.end());
  replicas_.erase(std::unique(replicas_.begin(), replicas_.end()), replicas_.end());
  for (uint32_t r = 0; r < replicas_.size(); ++r) {
    for (uint32_t i = 0; i < virtual_nodes; ++i)
      points_.emplace_back(ring_hash(replicas_[r] + "#" + std::to_string(i)), r);
  }
  std::sort(points_.begin(), points_.end());
}

std::vector<uint32_t> ReplicaRing::walk(uint64_t position) const {
  std::vector<uint32_t> order;
  if (points_.empty()) return order;
  const auto start = static_cast<std::size_t>(
      std::lower_bound(points_.begin(), points_.end(), std::make_pair(position, uint32_t{0}),
                       [](const auto& a, const auto& b) { return a.first < b.first; }) -
      points_.begin());
  std::vector<bool> seen(replicas_.size(), false);
  for (std::size_t k = 0; k < points_.size() && order.size() < replicas_.size(); ++k) {
    const uint32_t owner = points_[(start + k) % points_.size()].second;
    if (!seen[owner]) {
      seen[owner] = true;
      order.push_back(owner);
    }
  }
  return order;
}

std::map<uint64_t, uint32_t> ReplicaRing::assign(const std::map<uint64_t, uint64_t>& counts,
                                                 double load_factor) const {
  std::map<uint64_t, uint32_t> owner;
  if (replicas_.empty()) return owner;
  uint64_t total = 0;
  for (const auto& [key, count] : counts) total += count;
  const double capacity = std::ceil(load_factor * double(total) / double(replicas_.size()));
  std::vector<std::pair<uint64_t, uint64_t>> order(counts.begin(), counts.end());  // (key, count)
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) {
    return a.second != b.second ? a.second > b.second : a.first < b.first;
  });
  std::vector<uint64_t> load(replicas_.size(), 0);
  for (const auto& [key, count] : order) {
    const std::vector<uint32_t> walk_order = walk(key);
    uint32_t chosen = walk_order.front();
    bool fits = false;
    for (const uint32_t r : walk_order) {
      if (double(load[r] + count) <= capacity) {
        chosen = r;
        fits = true;
        break;
      }
    }
    if (!fits) {
      for (const uint32_t r : walk_order)
        if (load[r] < load[chosen]) chosen = r;
    }
    owner[key] = chosen;
    load[chosen] += count;
  }
  return owner;
}

}  // namespace outcore::client
