// What the parts of one pack share (scene_packer.cpp builds it, the
// partitions and the commit read and update it): the options, the memory plan
// and the limits derived from it, the phase timings, and the out-of-core
// statistics of the summary. Also the vocabulary of re-streamable triangle
// sets (SourceStream) that the partitions pass around.
//
// Thread-safety: one pack, one thread; the partitions' worker threads only
// read it (check_cancel()).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "core/geometry/aabb.h"
#include "core/geometry/triangle.h"
#include "core/store/manifest.h"
#include "core/store/pack_memory_plan.h"
#include "core/store/scene_packer.h"
#include "core/util/cancellation.h"
#include "core/util/status.h"

namespace outcore::packing {

struct PackContext {
  explicit PackContext(const PackOptions& options) : options(options) {}

  const PackOptions& options;
  MemoryPlan memory{};
  uint64_t group_capacity = 0;   // triangles that fit in memory at once
  uint32_t brick_triangles = 0;  // the target in effect: the option's, or the default's
  std::string temp_dir;          // the store being built; spill files live there too
  PackPhaseSeconds phases;
  uint64_t spill_bytes = 0;
  uint32_t levels = 0;  // out-of-core levels reached

  Status check_cancel() const { return cancel_requested() ? cancelled("pack interrupted") : Status::Ok(); }
};

// Wall time of a scope, added to one of PackPhaseSeconds' fields.
class PhaseTimer {
 public:
  explicit PhaseTimer(double& sink) : sink_(sink), start_(std::chrono::steady_clock::now()) {}
  ~PhaseTimer() { sink_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }
  PhaseTimer(const PhaseTimer&) = delete;
  PhaseTimer& operator=(const PhaseTimer&) = delete;

 private:
  double& sink_;
  std::chrono::steady_clock::time_point start_;
};

// What the scan learns about the inputs: the manifest's input records, counts
// and bounds.
struct ScanResult {
  std::vector<InputRecord> inputs;
  uint64_t triangles = 0;
  uint64_t degenerate = 0;
  Aabb bounds;
  Aabb centroid_bounds;
};

using PackedBatchFn = std::function<Status(std::span<const PackedTriangle>)>;
// A re-streamable set of tagged triangles: the inputs themselves or a spill file.
using PackedStream = std::function<Status(const PackedBatchFn&)>;
struct SourceStream {
  PackedStream stream;
  bool cheap = false;  // re-streaming beats a spill round trip
};

}  // namespace outcore::packing
