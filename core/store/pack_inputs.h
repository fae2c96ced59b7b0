// PackInputs: the pack's inputs as open TriangleSources, the scan that counts
// and bounds them (refusing non-finite or huge vertices and inputs beyond
// 32-bit primitive ids), and their triangles as one re-streamable stream
// tagged with geometry and primitive ids, which checks that no input changed
// since the scan.
//
// Thread-safety: one thread at a time (a TriangleSource is single-threaded);
// the RangeEmitters it hands out are const and may run on several threads.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/io/triangle_source.h"
#include "core/store/pack_context.h"

namespace outcore::packing {

class PackInputs {
 public:
  explicit PackInputs(PackContext& context) : context_(context) {}

  // Opens every input; lifetime meshes (gen:city bases, .npz meshes) are added to the memory
  // plan (context.memory.generator_meshes), within half of the budget.
  Status open(const SourceOptions& file_options);
  // One RangeEmitter per input when every input has one (generated scenes),
  // else none: the generated partition needs all inputs in ranges.
  std::vector<const RangeEmitter*> range_emitters() const;
  std::vector<std::string> descriptions() const;
  // Whether every input re-streams cheaper than a spill round trip.
  bool all_cheap_to_restream() const;
  // Streams every input once: counts, bounds, degenerates.
  Status scan(ScanResult& scan) const;
  // The inputs' triangles tagged with ids, as counted by the scan in `scan`.
  PackedStream stream(const ScanResult& scan);
  // Closes the inputs; readers' spill files go with them, so that they never
  // end up in the store.
  void close() { sources_.clear(); }

 private:
  PackContext& context_;
  std::vector<std::unique_ptr<TriangleSource>> sources_;
};

// Refuses an input of more triangles than 32-bit primitive ids can name.
Status check_primitive_id_range(size_t input, const InputRecord& record);
// The scan's verdict on inputs without triangles: a warning, or an error with
// --strict or when the whole scene is empty.
Status check_empty_inputs(const ScanResult& scan, bool strict);

}  // namespace outcore::packing
