// TriangleSource: every scene input (OBJ, PLY or .npz file, procedural generator)
// streams its triangles through this one interface, in primitive-id order, in
// batches, so that memory does not grow with the input's size. TriangleSink is
// the receiving end (the packer, a test, `outcore info` of an input).
//
// Contract: stream() delivers triangle k of the input as the k-th triangle over
// all batches, where k is the brief's primitive_id (file order, polygons
// fan-triangulated (v0,vi,vi+1), PLY strips expanded with alternating winding,
// degenerate triangles kept). stream() may be called again and yields the same
// triangles bit for bit. Errors name the file and line (or parameter). A sink
// error stops the stream and is returned unchanged.
//
// Thread-safety: a source is used by one thread at a time.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

// How a file reader may use memory and disk. The packer derives these from its
// --mem-mb budget and its temporary directory; the defaults (no limit) suit a
// quick look at a small input.
struct SourceOptions {
  // Most bytes an OBJ or PLY reader may hold for vertex positions (12 B per
  // vertex) and, when the file has more, for resolving its faces out of core
  // (core/io/vertex_spill.h). 0: no limit, vertices are always held.
  uint64_t vertex_memory_bytes = 0;
  // Where out-of-core readers keep their temporary files; empty: $TMPDIR or /tmp.
  std::string temp_dir;
};

// What a source may hold in memory for its lifetime (gen:city's welded base
// mesh, an .npz input's mesh: TriangleSource::held_memory_bytes()); the
// defaults mean no limit.
struct HeldMemoryLimit {
  uint64_t bytes = 0;  // 0: no limit
  std::string origin;  // where the limit comes from, for messages ("half of --mem-mb 1024")
};

class TriangleSink {
 public:
  virtual ~TriangleSink() = default;
  virtual Status consume(std::span<const Triangle> batch) = 0;
};

class TriangleBatcher;

// A capability of sources that can produce any range of their primitive ids
// on their own (procedural generators): the packer then cuts the input into
// chunks generated on all cores instead of streaming it once.
//
// Thread-safety: const; emit_range() may run on several threads at once.
class RangeEmitter {
 public:
  virtual ~RangeEmitter() = default;
  // Exact number of triangles of the input.
  virtual uint64_t triangle_count() const = 0;
  // Appends triangles [first, last) of primitive-id order (last clamped to
  // triangle_count()), bit-identical to those of a full stream, in time
  // O(last - first) plus a small setup; `out` is not finished.
  virtual Status emit_range(uint64_t first, uint64_t last, TriangleBatcher& out) const = 0;
  // Ranges starting at multiples of this are cheapest (e.g. one city copy).
  virtual uint64_t range_granularity() const = 0;
};

class TriangleSource {
 public:
  virtual ~TriangleSource() = default;
  // What the user wrote (path or gen: spec); used in messages and the manifest.
  virtual const std::string& description() const = 0;
  virtual Status stream(TriangleSink& sink) = 0;
  // True when streaming again costs less than writing the triangles to disk
  // and reading them back (generators); the packer then re-streams instead of
  // spilling.
  virtual bool cheap_to_restream() const { return false; }
  // Bytes the source holds for its whole lifetime (a generator's base mesh),
  // which the packer's memory plan must reserve.
  virtual uint64_t held_memory_bytes() const { return 0; }
  // This source's RangeEmitter when it can emit ranges cheaply; nullptr
  // otherwise (files: only a full stream is cheap).
  virtual const RangeEmitter* range_emitter() const { return nullptr; }
};

// Sink that forwards batches to a callable: Status(std::span<const Triangle>).
template <class Fn>
class CallbackSink final : public TriangleSink {
 public:
  explicit CallbackSink(Fn fn) : fn_(std::move(fn)) {}
  Status consume(std::span<const Triangle> batch) override { return fn_(batch); }

 private:
  Fn fn_;
};

// Every triangle `source` streams, in memory: for inputs known to be small
// (tests, stress scenes, benchmarks).
inline Expected<std::vector<Triangle>> read_all(TriangleSource& source) {
  std::vector<Triangle> out;
  CallbackSink sink([&](std::span<const Triangle> batch) {
    out.insert(out.end(), batch.begin(), batch.end());
    return Status::Ok();
  });
  OUTCORE_RETURN_IF_ERROR(source.stream(sink));
  return out;
}

// Collects triangles into fixed-size batches for a sink; sources call add() per
// triangle and finish() at the end.
class TriangleBatcher {
 public:
  static constexpr std::size_t kBatchSize = 4096;
  explicit TriangleBatcher(TriangleSink& sink) : sink_(sink) {}

  Status add(const Triangle& t) {
    buffer_[size_++] = t;
    if (size_ == kBatchSize) return flush();
    return Status::Ok();
  }
  Status flush() {
    if (size_ == 0) return Status::Ok();
    const std::size_t n = size_;
    size_ = 0;
    return sink_.consume(std::span<const Triangle>(buffer_.data(), n));
  }
  Status finish() { return flush(); }

 private:
  TriangleSink& sink_;
  std::array<Triangle, kBatchSize> buffer_;
  std::size_t size_ = 0;
};

}  // namespace outcore
