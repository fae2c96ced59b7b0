#include "core/store/generated_chunks.h"

#include <algorithm>

#include "core/geometry/coordinate_limits.h"
#include "core/store/pack_inputs.h"
#include "core/util/progress.h"

namespace outcore::packing {

namespace {

// Per-chunk results of the scan, merged in chunk order.
struct ChunkScan {
  uint64_t degenerate = 0;
  uint64_t first_bad = ~uint64_t{0};  // primitive id of the first triangle vertex_problem() refuses, or none
  const char* problem = nullptr;      // and why
  Aabb bounds, centroid_bounds;
};

}  // namespace

uint64_t GeneratedChunks::total_triangles() const {
  uint64_t total = 0;
  for (const RangeEmitter* emitter : emitters_) total += emitter->triangle_count();
  return total;
}

void GeneratedChunks::make() {
  const uint64_t total = total_triangles();
  // About 1/512 of the budget per chunk (so the filter pipeline's buffers stay
  // small), 16 K .. 128 K triangles, more for scenes beyond kMaxChunks chunks.
  const uint64_t budget = context_.options.memory_mb * kMiB;
  uint64_t target = std::clamp<uint64_t>(budget / 512 / sizeof(PackedTriangle), 1 << 14, 1 << 17);
  target = std::max(target, (total + kMaxChunks - 1) / kMaxChunks);
  chunks_.clear();
  max_chunk_ = 0;
  for (uint32_t g = 0; g < emitters_.size(); ++g) {
    const uint64_t count = emitters_[g]->triangle_count();
    const uint64_t step = std::max<uint64_t>(1, emitters_[g]->range_granularity());
    // Whole copies/rows when they are not much larger than the target (a
    // partial copy still transforms all of the copy's vertices); otherwise the
    // generator emits partial ones.
    const uint64_t size = step <= target ? target / step * step : (step <= 4 * target ? step : target);
    for (uint64_t first = 0; first < count; first += size) {
      chunks_.push_back({g, first, std::min(count, first + size), Aabb{}});
      max_chunk_ = std::max(max_chunk_, chunks_.back().last - first);
    }
  }
  context_.memory.chunk_table =
      chunks_.size() * (sizeof(InputChunk) + sizeof(ChunkScan) + 4 * sizeof(uint32_t));
  context_.memory.filter_buffers =
      uint64_t{kFilterTokens} * max_chunk_ * (sizeof(PackedTriangle) + sizeof(uint32_t));
}

Status GeneratedChunks::scan(ScanResult& scan) {
  PhaseTimer timer(context_.phases.scan);
  ProgressBar bar("scan", total_triangles(), "tris", context_.options.show_progress);
  std::vector<ChunkScan> results(chunks_.size());
  OUTCORE_RETURN_IF_ERROR(parallel_over(chunks_.size(), [&](std::size_t i) {
    ChunkScan& r = results[i];
    Status s = generate(chunks_[i], [&](std::span<const Triangle> batch, uint64_t id) -> Status {
      for (std::size_t k = 0; k < batch.size(); ++k) {
        const Triangle& t = batch[k];
        if (const char* problem = vertex_problem(t)) {
          if (id + k < r.first_bad) r.problem = problem;
          r.first_bad = std::min(r.first_bad, id + k);
          continue;
        }
        r.degenerate += t.is_degenerate();
        r.bounds.extend(t.bounds());
        r.centroid_bounds.extend(t.centroid());
      }
      bar.advance(batch.size());
      return Status::Ok();
    });
    chunks_[i].centroid_bounds = r.centroid_bounds;
    return s;
  }));
  bar.finish();
  // Merge in input order; min/max and sums are exact, so any order would do.
  for (uint32_t g = 0; g < emitters_.size(); ++g) {
    InputRecord record;
    record.spec = descriptions_[g];
    record.triangle_count = emitters_[g]->triangle_count();
    for (std::size_t i = 0; i < chunks_.size(); ++i) {
      if (chunks_[i].input != g) continue;
      const ChunkScan& r = results[i];
      if (r.first_bad != ~uint64_t{0}) {
        return invalid_argument("input " + std::to_string(g) + " '" + record.spec + "': triangle " +
                                std::to_string(r.first_bad) + " " + r.problem);
      }
      record.degenerate_count += r.degenerate;
      scan.bounds.extend(r.bounds);
      scan.centroid_bounds.extend(r.centroid_bounds);
    }
    OUTCORE_RETURN_IF_ERROR(check_primitive_id_range(g, record));
    scan.triangles += record.triangle_count;
    scan.degenerate += record.degenerate_count;
    scan.inputs.push_back(std::move(record));
  }
  if (scan.triangles == 0) return invalid_argument("the scene is empty: no input has any triangle");
  return Status::Ok();
}

}  // namespace outcore::packing
