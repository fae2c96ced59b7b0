// CityGenerator (`gen:city`): many randomly transformed copies of one base mesh
// (a file or another gen: spec), laid out on a jittered square grid. Each copy
// gets a random rotation about y, a uniform scale in [0.5, 1.5], a jitter in x/z
// and a small y offset, all derived from (seed, copy index) only.
//
// Triangle k of copy c has primitive id c * base_count + k (copy-major). A base
// vertex p becomes M_c p + t_c (see CopyTransform; the rotation and scale act
// about the base's bounding-box centre), computed in double and rounded to float
// once. With the default spacing, copies never overlap: a copy reaches at most
// 0.3 cells from its jittered centre, which is at most 0.15 cells off the cell's.
//
// Memory: one copy of the base mesh, read once at creation through
// open_triangle_source(of) and kept welded (IndexedMesh: 12 B per unique vertex
// + 12 B per triangle), plus, per emitting thread, 12 B per base vertex of
// scratch when a range covers enough of a copy to pay for it (else corners are
// transformed one by one, so the scratch never exceeds 36 B per triangle of
// the range); independent of `copies`. GeneratorOptions::mesh_memory_bytes
// bounds the base while it is read (refused up front when its triangles alone
// exceed it), and reading it stops on cancellation (cancellation.h).
//
// Parameters: of (base mesh, default gen:sphere?level=3; wrap a nested spec in
// parentheses), copies (1..1e9, default 100), seed (0..2^63-1, default 1),
// spacing (grid cell size, > 0, default 2.5 x the base's bounding-box diagonal),
// tilt (degrees, -90..90, default 0: the whole city turned about the x axis
// through the origin after the copies are placed, so that its flat layer of
// copies lies oblique to every axis: the rotated scene on which oriented
// brick bounds and BSP planes are measured; tilt=0 is bitwise the untilted city).
// copies * base_count must stay <= 2^32 - 1 (uint32 primitive ids).
//
// Thread-safety: see Generator (emit() is const and stateless).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/gen/gen_spec.h"
#include "core/gen/generator.h"
#include "core/gen/generator_factory.h"
#include "core/gen/indexed_mesh.h"

namespace outcore {

struct CityConfig {
  std::string of = "gen:sphere?level=3";  // the base mesh: a .obj/.ply path or a gen: spec
  int64_t copies = 100;                   // number of copies, laid out on ceil(sqrt(copies))^2 cells
  int64_t seed = 1;                       // drives every copy's transform
  std::optional<double> spacing;          // cell size; default 2.5 x the base's bounding diagonal
  double tilt_degrees = 0;                // the whole city turned about x

  static constexpr int64_t kMaxCopies = 1'000'000'000;
  static Expected<CityConfig> parse(const GenSpec& spec);
};

// The similarity transform of one copy: scale, rotation by an angle a about y,
// translation (the base's centre folded into t):
//   x' = sc * x + ss * z + t.x,  y' = scale * y + t.y,  z' = sc * z - ss * x + t.z
// with sc = scale * cos(a), ss = scale * sin(a); computed in double.
// With a tilt, the result is then turned about x: y' = tc y - ts z,
// z' = ts y + tc z (still in double, rounded once).
struct CopyTransform {
  double sc = 1, ss = 0, scale = 1;
  Vec3d t;
  bool tilted = false;
  double tc = 1, ts = 0;
  Vec3f apply(const Vec3f& p) const {
    const double x = p.x, y = p.y, z = p.z;
    const Vec3d placed(sc * x + ss * z + t.x, scale * y + t.y, sc * z - ss * x + t.z);
    if (!tilted) return to_vertex(placed);
    return to_vertex(Vec3d(placed.x, tc * placed.y - ts * placed.z, ts * placed.y + tc * placed.z));
  }
};

class CityGenerator final : public Generator {
 public:
  // Reads the base mesh (errors from `of` are returned with context naming it).
  static Expected<std::unique_ptr<CityGenerator>> create(const GenSpec& spec,
                                                         const GeneratorOptions& options = {});

  const CityConfig& config() const { return config_; }
  uint64_t triangle_count() const override {
    return static_cast<uint64_t>(config_.copies) * base_.triangle_count();
  }
  Status emit(TriangleBatcher& out) const override;
  // By copies: a range transforms only the copies it touches.
  Status emit_range(uint64_t first, uint64_t last, TriangleBatcher& out) const override;
  bool has_fast_ranges() const override { return true; }
  uint64_t range_granularity() const override { return base_.triangle_count(); }

  // The base mesh exactly as `of` streamed it (triangle k = base().triangle(k)).
  const IndexedMesh& base() const { return base_; }
  // The base mesh, held for the generator's lifetime.
  uint64_t held_memory_bytes() const override {
    return base_.vertices.capacity() * sizeof(Vec3f) +
           base_.triangles.capacity() * sizeof(base_.triangles[0]);
  }
  double cell_size() const { return cell_; }
  CopyTransform copy_transform(int64_t copy) const;

 private:
  CityGenerator(std::string description, const CityConfig& config, IndexedMesh base);

  CityConfig config_;
  IndexedMesh base_;
  Vec3d centre_;     // centre of the base's bounding box
  double diagonal_;  // the base's bounding-box diagonal
  double cell_;      // grid cell size
  int64_t side_;     // cells per grid side
};

}  // namespace outcore
