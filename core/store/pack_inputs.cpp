#include "core/store/pack_inputs.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "core/geometry/coordinate_limits.h"
#include "core/source/source_factory.h"
#include "core/util/progress.h"

namespace outcore::packing {

Status PackInputs::open(const SourceOptions& file_options) {
  const PackOptions& options = context_.options;
  MemoryPlan& memory = context_.memory;
  // Half the budget, as for --vertex-mem-mb: the rest must still hold a brick.
  const uint64_t allowance = options.memory_mb * kMiB / 2;
  const std::string origin = "half of --mem-mb " + std::to_string(options.memory_mb);
  for (const std::string& spec : options.inputs) {
    OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
    // Bases of several cities and .npz meshes are held at once, so each gets
    // what is left (a held mesh never exceeds the limit it was read under: at
    // least 1 is left).
    HeldMemoryLimit held;
    held.bytes = std::max<uint64_t>(1, allowance - memory.generator_meshes);
    held.origin = memory.generator_meshes == 0
                      ? origin
                      : "what the meshes of earlier inputs (gen:city bases, .npz files) left of " + origin;
    auto source = open_triangle_source(spec, file_options, held);
    if (!source.ok()) return source.status();
    memory.generator_meshes += (*source)->held_memory_bytes();
    sources_.push_back(std::move(source).value());
  }
  return Status::Ok();
}

std::vector<const RangeEmitter*> PackInputs::range_emitters() const {
  std::vector<const RangeEmitter*> emitters;
  for (const auto& source : sources_) {
    const RangeEmitter* emitter = source->range_emitter();
    if (emitter == nullptr) return {};
    emitters.push_back(emitter);
  }
  return emitters;
}

std::vector<std::string> PackInputs::descriptions() const {
  std::vector<std::string> names;
  for (const auto& source : sources_) names.push_back(source->description());
  return names;
}

bool PackInputs::all_cheap_to_restream() const {
  bool all_cheap = true;
  for (const auto& source : sources_) all_cheap &= source->cheap_to_restream();
  return all_cheap;
}

Status check_primitive_id_range(size_t input, const InputRecord& record) {
  if (record.triangle_count < 0xffffffffull) return Status::Ok();
  return invalid_argument("input " + std::to_string(input) + " '" + record.spec + "' has " +
                          std::to_string(record.triangle_count) +
                          " triangles; primitive ids are 32-bit, so an input may hold at most 4294967294");
}

Status check_empty_inputs(const ScanResult& scan, bool strict) {
  // A file that is not what it claims (an OBJ of unknown statements) parses
  // to nothing; silently packing the rest would hide the mistake.
  for (size_t g = 0; g < scan.inputs.size(); ++g) {
    if (scan.inputs[g].triangle_count != 0) continue;
    const std::string what = "input " + std::to_string(g) + " '" + scan.inputs[g].spec + "' has no triangles";
    if (strict) return invalid_argument(what + " (--strict)");
    if (scan.triangles != 0) spdlog::warn("{}; it contributes nothing to the scene", what);
  }
  if (scan.triangles == 0) return invalid_argument("the scene is empty: no input has any triangle");
  return Status::Ok();
}

Status PackInputs::scan(ScanResult& scan) const {
  PhaseTimer timer(context_.phases.scan);
  ProgressBar bar("scan", 0, "tris", context_.options.show_progress);
  for (size_t g = 0; g < sources_.size(); ++g) {
    InputRecord record;
    record.spec = sources_[g]->description();
    auto sink = CallbackSink([&](std::span<const Triangle> batch) -> Status {
      OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
      for (const Triangle& t : batch) {
        if (const char* problem = vertex_problem(t)) {
          return invalid_argument("input " + std::to_string(g) + " '" + record.spec + "': triangle " +
                                  std::to_string(record.triangle_count) + " " + problem);
        }
        record.degenerate_count += t.is_degenerate();
        scan.bounds.extend(t.bounds());
        scan.centroid_bounds.extend(t.centroid());
        ++record.triangle_count;
      }
      bar.advance(batch.size());
      return Status::Ok();
    });
    OUTCORE_RETURN_IF_ERROR(sources_[g]->stream(sink));
    OUTCORE_RETURN_IF_ERROR(check_primitive_id_range(g, record));
    scan.triangles += record.triangle_count;
    scan.degenerate += record.degenerate_count;
    scan.inputs.push_back(std::move(record));
  }
  bar.finish();
  return check_empty_inputs(scan, context_.options.strict);
}

PackedStream PackInputs::stream(const ScanResult& scan) {
  return [this, &scan](const PackedBatchFn& fn) -> Status {
    std::vector<PackedTriangle> packed;
    packed.reserve(TriangleBatcher::kBatchSize);
    for (size_t g = 0; g < sources_.size(); ++g) {
      uint32_t next_id = 0;
      const uint64_t expected = scan.inputs[g].triangle_count;
      auto sink = CallbackSink([&](std::span<const Triangle> batch) -> Status {
        OUTCORE_RETURN_IF_ERROR(context_.check_cancel());
        if (next_id + batch.size() > expected) {
          return failed_precondition("input '" + scan.inputs[g].spec + "' changed while being packed");
        }
        packed.clear();
        for (const Triangle& t : batch) packed.push_back({t, static_cast<uint32_t>(g), next_id++});
        return fn(packed);
      });
      OUTCORE_RETURN_IF_ERROR(sources_[g]->stream(sink));
      if (next_id != expected) {
        return failed_precondition("input '" + scan.inputs[g].spec + "' changed while being packed");
      }
    }
    return Status::Ok();
  };
}

}  // namespace outcore::packing
