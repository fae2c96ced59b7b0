// GeneratedChunks: generated inputs (every input a RangeEmitter, see
// core/io/triangle_source.h) cut into chunks of primitive ids that are
// generated on all cores and merged in chunk order, so the result does not
// depend on the thread count; and the parallel scan over those chunks, which
// also records each chunk's centroid box (which groups it can touch).
//
// Thread-safety: make() and scan() on one thread; generate() is const and
// runs on any number of threads at once.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/io/triangle_source.h"
#include "core/store/pack_context.h"

namespace outcore::packing {

// These feed the MemoryPlan, so they must not depend on the machine either.
inline constexpr uint32_t kFilterTokens = 8;     // chunks in flight in the filter pipeline
inline constexpr uint64_t kMaxChunks = 1 << 16;  // chunks grow with the scene beyond this

// Primitive ids [first, last) of one generated input.
struct InputChunk {
  uint32_t input = 0;
  uint64_t first = 0, last = 0;
  Aabb centroid_bounds;  // from the scan; tells which groups the chunk can touch
};

class GeneratedChunks {
 public:
  // emitters[g] and descriptions[g] belong to input g.
  GeneratedChunks(PackContext& context, std::vector<const RangeEmitter*> emitters,
                  std::vector<std::string> descriptions)
      : context_(context), emitters_(std::move(emitters)), descriptions_(std::move(descriptions)) {}

  // Cuts the inputs into chunks and reserves the chunk table and the filter
  // buffers in the memory plan.
  void make();
  // Generates every chunk once on all cores: counts, bounds, degenerates.
  Status scan(ScanResult& scan);
  // Streams one chunk's triangles to fn(batch, primitive id of batch[0]).
  template <class Fn>
  Status generate(const InputChunk& chunk, Fn&& fn) const;

  const std::vector<InputChunk>& chunks() const { return chunks_; }
  uint64_t max_chunk_triangles() const { return max_chunk_; }
  uint64_t total_triangles() const;

 private:
  PackContext& context_;
  std::vector<const RangeEmitter*> emitters_;
  std::vector<std::string> descriptions_;
  std::vector<InputChunk> chunks_;
  uint64_t max_chunk_ = 0;  // triangles
};

// Runs fn(i) for every index in [0, count) on all cores; returns the error of
// the lowest failing index (others stop early).
template <class Fn>
Status parallel_over(std::size_t count, Fn&& fn) {
  std::atomic<bool> failed{false};
  std::mutex mutex;
  std::size_t error_index = count;
  Status error;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        if (failed.load(std::memory_order_relaxed)) return;
                        Status s = fn(i);
                        if (!s.ok()) {
                          std::lock_guard lock(mutex);
                          if (i < error_index) {
                            error_index = i;
                            error = std::move(s);
                          }
                          failed = true;
                        }
                      }
                    });
  return error;
}

template <class Fn>
Status GeneratedChunks::generate(const InputChunk& chunk, Fn&& fn) const {
  uint64_t next = chunk.first;
  const std::string& description = descriptions_[chunk.input];
  auto sink = CallbackSink([&](std::span<const Triangle> batch) -> Status {
    OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
    if (next + batch.size() > chunk.last) {
      return internal_error("input '" + description + "' emitted more than triangles [" +
                            std::to_string(chunk.first) + ", " + std::to_string(chunk.last) + ")");
    }
    const uint64_t id = next;
    next += batch.size();
    return fn(batch, id);
  });
  // The batch buffer is ~150 KB: keep it off the worker's stack.
  auto batcher = std::make_unique<TriangleBatcher>(sink);
  OUTCORE_RETURN_IF_ERROR(emitters_[chunk.input]->emit_range(chunk.first, chunk.last, *batcher));
  OUTCORE_RETURN_IF_ERROR(batcher->finish());
  if (next != chunk.last) {
    return internal_error("input '" + description + "' emitted fewer than triangles [" +
                          std::to_string(chunk.first) + ", " + std::to_string(chunk.last) + ")");
  }
  return Status::Ok();
}

}  // namespace outcore::packing
