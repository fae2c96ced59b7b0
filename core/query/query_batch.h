// QueryBatch: one batch's rays and answers (closest hits, occlusion flags or
// every hit, by kKind) and its rays' validity flags, with the per-ray operations every
// strategy shares: reset, check, horizon, finish, trace at a brick.
//
// Thread-safety: a view; tasks touch disjoint rays.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <span>
#include <vector>

#include "core/accel/brick_accel.h"
#include "core/ray/query_types.h"
#include "core/ray/ray_problem.h"
#include "core/ray/ray_types.h"
#include "core/util/status.h"

namespace outcore {

// Where an every-hit batch puts its records: each brick visit's chunk is
// appended at once (one lock per chunk of up to QueryBatch::kTraceChunk rays).
struct AllHitsCollector {
  std::mutex mutex;
  std::vector<RayHitRecord> records;

  void append(const std::vector<RayHitRecord>& found) {
    if (found.empty()) return;
    const std::lock_guard lock(mutex);
    records.insert(records.end(), found.begin(), found.end());
  }
};

template <QueryKind kKind>
struct QueryBatch {
  std::span<const Ray> rays;
  Hit* hits = nullptr;          // closest hit
  uint8_t* occluded = nullptr;  // any hit
  // 1 per valid ray, written by validate_batch() (validated apart) or the
  // queued strategy's first pass; unused by the chunked strategies otherwise.
  uint8_t* valid = nullptr;
  // The rays were validated before any strategy ran (strict mode, or
  // reordering off): `valid` says, nothing is to be reset or counted again.
  bool validated_apart = false;
  // Every hit: hits per ray, and where the hits go (null: counts only).
  uint32_t* hit_counts = nullptr;
  AllHitsCollector* collector = nullptr;

  std::size_t size() const { return rays.size(); }

  // Ray i's answer before tracing (a miss).
  void reset_answer(std::size_t i) const {
    if constexpr (kKind == QueryKind::kClosestHit) {
      hits[i] = Hit{};
    } else if constexpr (kKind == QueryKind::kAnyHit) {
      occluded[i] = 0;
    } else {
      hit_counts[i] = 0;
    }
  }
  // 1 when ray i's answer is a hit.
  uint64_t answered_hit(std::size_t i) const {
    if constexpr (kKind == QueryKind::kClosestHit) return hits[i].is_hit();
    if constexpr (kKind == QueryKind::kAllHits) return hit_counts[i] != 0;
    return occluded[i] != 0;
  }
  // Resets ray i's answer; true when the ray is valid (ray_problem).
  bool reset_and_check(std::size_t i) const {
    reset_answer(i);
    return ray_is_valid(rays[i]);
  }
  // In the chunked strategies: whether ray i is to be traced. Validated
  // apart, its flag says; otherwise it is reset and checked here, and counted
  // in `invalid` when it is bad.
  bool chunk_ray_valid(std::size_t i, uint64_t& invalid) const {
    if (validated_apart) return valid[i] != 0;
    if (reset_and_check(i)) return true;
    ++invalid;
    return false;
  }
  // The largest distance at which a brick can still matter for ray i.
  float horizon(std::size_t i) const {
    if constexpr (kKind == QueryKind::kClosestHit) return std::min(rays[i].tfar, hits[i].t);
    return rays[i].tfar;
  }
  // Nothing further can change ray i's answer (an occlusion found; every
  // hit never finishes early).
  bool finished(std::size_t i) const {
    if constexpr (kKind == QueryKind::kAnyHit) return occluded[i] != 0;
    return false;
  }
  // Traces the rays `ids` at one brick (one virtual call per
  // kTraceChunk of them); returns how many found no hit there: nothing
  // nearer (or tied and preferred) than the hit the ray had, or still
  // unoccluded. The answers before are kept on the stack, a chunk at a time.
  static constexpr std::size_t kTraceChunk = 512;
  uint64_t trace(const BrickAccel& accel, std::span<const uint32_t> ids) const {
    uint64_t without_hit = 0;
    if constexpr (kKind == QueryKind::kClosestHit) {
      for (std::size_t from = 0; from < ids.size(); from += kTraceChunk) {
        const std::span<const uint32_t> chunk = chunk_at(ids, from);
        float t[kTraceChunk];
        uint32_t primitive[kTraceChunk], geometry[kTraceChunk];
        for (std::size_t k = 0; k < chunk.size(); ++k) {
          prefetch_ray(chunk[k]);
          const Hit& h = hits[chunk[k]];
          t[k] = h.t;
          primitive[k] = h.primitive_id;
          geometry[k] = h.geometry_id;
        }
        accel.intersect(chunk, rays.data(), hits);
        for (std::size_t k = 0; k < chunk.size(); ++k) {
          const Hit& h = hits[chunk[k]];
          // t compared by bits: a ray's miss may carry t = +inf or tfar.
          without_hit += std::bit_cast<uint32_t>(h.t) == std::bit_cast<uint32_t>(t[k]) &&
                         h.primitive_id == primitive[k] && h.geometry_id == geometry[k];
        }
      }
    } else if constexpr (kKind == QueryKind::kAnyHit) {
      for (std::size_t from = 0; from < ids.size(); from += kTraceChunk) {
        const std::span<const uint32_t> chunk = chunk_at(ids, from);
        for (const uint32_t i : chunk) prefetch_ray(i);
        accel.occluded(chunk, rays.data(), occluded);
        for (const uint32_t i : chunk) without_hit += occluded[i] == 0;
      }
    } else {
      without_hit = trace_all_hits(accel, ids);
    }
    return without_hit;
  }

 private:
  // The kTraceChunk ids of `ids` from `from` (fewer at the end).
  static std::span<const uint32_t> chunk_at(std::span<const uint32_t> ids, std::size_t from) {
    return ids.subspan(from, std::min(kTraceChunk, ids.size() - from));
  }

  // A queue's rays are scattered over the batch: asking for a chunk's rays at
  // once overlaps their cache misses, which the structure would otherwise
  // take one ray at a time (12 % of a sparse scene's warm incoherent batch).
  // Both ends: a ray need not sit within one cache line.
  void prefetch_ray(uint32_t i) const {
    __builtin_prefetch(&rays[i]);
    __builtin_prefetch(reinterpret_cast<const char*>(&rays[i]) + sizeof(Ray) - 1);
  }

  uint64_t trace_all_hits(const BrickAccel& accel, std::span<const uint32_t> ids) const {
    uint64_t with_hit = 0;
    if (collector == nullptr) {
      // Counting only: no records.
      for (std::size_t from = 0; from < ids.size(); from += kTraceChunk) {
        const std::span<const uint32_t> chunk = chunk_at(ids, from);
        uint32_t before[kTraceChunk];
        for (std::size_t k = 0; k < chunk.size(); ++k) {
          prefetch_ray(chunk[k]);
          before[k] = hit_counts[chunk[k]];
        }
        accel.count_hits(chunk, rays.data(), hit_counts);
        for (std::size_t k = 0; k < chunk.size(); ++k) with_hit += hit_counts[chunk[k]] != before[k];
      }
      return ids.size() - with_hit;
    }
    std::vector<RayHitRecord> found;
    for (std::size_t from = 0; from < ids.size(); from += kTraceChunk) {
      found.clear();
      const std::span<const uint32_t> chunk = chunk_at(ids, from);
      for (const uint32_t i : chunk) prefetch_ray(i);
      accel.all_hits(chunk, rays.data(), found);
      // A ray's records are consecutive (structures answer ray by ray).
      for (std::size_t k = 0; k < found.size(); ++k) {
        ++hit_counts[found[k].ray];
        with_hit += k == 0 || found[k].ray != found[k - 1].ray;
      }
      collector->append(found);
    }
    return ids.size() - with_hit;
  }
};

// Resets every answer and sets the validity flags, in parallel chunks, adding
// the bad rays to `invalid`. With `strict`, INVALID_ARGUMENT naming the first
// bad ray of the batch.
template <QueryKind kKind>
Status validate_batch(const QueryBatch<kKind>& batch, bool strict, uint64_t& invalid);

}  // namespace outcore
