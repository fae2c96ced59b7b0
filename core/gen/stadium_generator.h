// StadiumGenerator (`gen:stadium`): "teapot in a stadium", a tiny dense object
// in a huge sparse enclosure, the classic worst case for spatial subdivision.
// The enclosure is an open box: a floor [-size, size]^2 at y = 0 of
// segments x segments quads and four walls of height size/2 of segments x
// max(1, segments/8) quads, all facing inwards (768 triangles by default). The
// object is an icosphere (see SphereGenerator) of radius `object` centred at
// (0, 1.5 * object, 0), half a radius above the floor.
//
// Order (primitive ids): floor, walls +x, -x, +z, -z (each row-major), then the
// object. Memory: O(level).
//
// Parameters: size (enclosure half-extent, > 0, default 1000), level (object's
// icosphere level, 0..12, default 6), object (object radius, > 0, at most
// size/4, default 1), segments (enclosure tessellation, 1..1024, default 16).
//
// Thread-safety: see Generator (emit() is const and stateless).
#pragma once

#include <memory>

#include "core/gen/gen_spec.h"
#include "core/gen/generator.h"
#include "core/gen/sphere_generator.h"

namespace outcore {

struct StadiumConfig {
  double size = 1000.0;  // enclosure half-extent in x and z; walls are size/2 high
  int level = 6;         // the object's icosphere level (20 * 4^level triangles)
  double object = 1.0;   // the object's radius
  int segments = 16;     // floor quads per side; wall quads per side

  static constexpr int kMaxSegments = 1024;
  static Expected<StadiumConfig> parse(const GenSpec& spec);
};

class StadiumGenerator final : public Generator {
 public:
  StadiumGenerator(std::string description, const StadiumConfig& config);
  static Expected<std::unique_ptr<StadiumGenerator>> create(const GenSpec& spec);

  const StadiumConfig& config() const { return config_; }
  // Triangles of the floor and walls (they come first).
  uint64_t enclosure_triangle_count() const;
  uint64_t triangle_count() const override { return enclosure_triangle_count() + object_.triangle_count(); }
  Status emit(TriangleBatcher& out) const override;

 private:
  int wall_rows() const { return config_.segments / 8 > 1 ? config_.segments / 8 : 1; }

  StadiumConfig config_;
  SphereGenerator object_;
};

}  // namespace outcore
