// Generator: the common base of the procedural sources (sphere, torus, terrain,
// city, stadium). A generator knows its exact triangle count up front and
// emits its triangles in primitive-id order into a TriangleBatcher; stream()
// wraps that for any sink. Generators can be composed (the stadium emits a
// sphere into its own batcher) because emit() is public and const.
//
// Every generator is a pure function of its configuration: emit() keeps no
// state between calls, so stream() yields the same triangles bit for bit each
// time. Vertices are computed in double and rounded to float once.
//
// Thread-safety: emit() and triangle_count() are const and touch no shared
// state, so one generator may be streamed by several threads at once, each with
// its own sink (the TriangleSource contract only promises one thread at a time).
#pragma once

#include <cstdint>
#include <string>

#include "core/geometry/vec3.h"
#include "core/io/triangle_source.h"

namespace outcore {

// Largest triangle count of one input: primitive ids are uint32 and
// 4294967295 means "miss", so ids run 0 .. 2^32 - 2.
inline constexpr uint64_t kMaxGeneratedTriangles = 0xFFFFFFFFull;

class Generator : public TriangleSource, public RangeEmitter {
 public:
  const std::string& description() const override { return description_; }
  Status stream(TriangleSink& sink) override;
  // Generating is faster than any disk round trip (writing and reading back).
  bool cheap_to_restream() const override { return true; }

  // Exact number of triangles stream() delivers.
  uint64_t triangle_count() const override = 0;
  // Appends the triangles, in primitive-id order, to `out` (without finishing it).
  virtual Status emit(TriangleBatcher& out) const = 0;
  // Appends triangles [first, last) of primitive-id order (last clamped to
  // triangle_count()), bit-identical to those of emit(): disjoint ranges can
  // be generated on several threads and concatenated. The default generates
  // everything and keeps the range, so it costs O(triangle_count()).
  Status emit_range(uint64_t first, uint64_t last, TriangleBatcher& out) const override;
  // True when emit_range costs O(last - first) plus a small setup, so callers
  // may cut the generator into many ranges.
  virtual bool has_fast_ranges() const { return false; }
  // Ranges starting at multiples of this are cheapest (e.g. one city copy).
  uint64_t range_granularity() const override { return 1; }
  // Only generators with fast ranges offer them: the default emit_range
  // generates everything once per range.
  const RangeEmitter* range_emitter() const override { return has_fast_ranges() ? this : nullptr; }

 protected:
  explicit Generator(std::string description) : description_(std::move(description)) {}

 private:
  std::string description_;
};

// Rounds a double-precision point to the float vertex that is emitted.
inline Vec3f to_vertex(const Vec3d& p) {
  return Vec3f(p);
}

}  // namespace outcore
