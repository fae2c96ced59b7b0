// The scenes of the numerical stress suite (issue 5): each is a set of
// triangles with the user's ids and a set of rays, every ray with what it
// must do (hit, miss, or whatever the float64 reference says). Families:
//
//   closed   closed meshes (icosphere, torus, and the closed models fandisk,
//            homer, spot, beast when models_dir has them), normalised to unit
//            size about the origin, then as is, translated by (T, T, T) for
//            T = 1e3, 1e5, 1e6 and scaled by 1e-4 and 1e6 (all in double,
//            rounded to float once, so shared vertices stay shared). Rays
//            start at an interior point and are aimed exactly at every vertex
//            and every edge midpoint: direction = target - origin computed
//            in float (so the ray is the float ray; at large offsets the
//            subtraction is exact and the ray passes exactly through the
//            vertex). Each must hit: a miss is a leak.
//   axis     axis-parallel rays (the other two direction components +0.0 or
//            -0.0) from interior points of a sphere, and down onto a flat
//            grid at its vertices, edge midpoints and cell centres.
//   grazing  rays in the plane of a face (through its interior and along an
//            edge) of a sphere and of the grid: judged by the reference only.
//   sliver   bipyramids of 1000 long thin triangles, one nearly flat, with
//            zero-area triangles added along the equator, origin exactly at
//            the centre (so rays to the equator run in the plane of its edges).
//   segment  tnear / tfar exactly at the (exactly representable) hit distance
//            on the grid: tfar = t must hit, tnear = t must miss.
//   seam     a sphere and a torus packed into tiny bricks (16 triangles) and
//            into one brick, traced through the query engine: the tiny-brick
//            answers must equal the one-brick answers and not leak.
//
// Interior points: the centroid for the sphere and bipyramids, a point on the
// core circle for the torus, and for models the grid point nearest the centre
// that float64 ray parity (three directions, all odd) finds inside; checked
// again after every translation and scaling.
//
// Thread-safety: plain functions and values.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/ray/ray_types.h"
#include "core/store/brick_data.h"
#include "core/util/status.h"
#include "core/util/temporary_directory.h"

namespace outcore {

enum class StressExpect : uint8_t { kReference, kHit, kMiss };

// Removes its directory (packed stores of the seam scenes) when destroyed.
// The name is made unique by mkdtemp: a leftover directory of an earlier
// process with the same pid must not make the suite fail.
class StressWorkspace {
 public:
  static Expected<std::shared_ptr<StressWorkspace>> create();
  std::filesystem::path path() const { return directory_.path(); }

 private:
  StressWorkspace() = default;
  TemporaryDirectory directory_;
};

struct StressScene {
  std::string name;    // e.g. "sphere +1e6"
  std::string family;  // closed, axis, grazing, sliver, segment, seam
  std::vector<Triangle> triangles;
  std::vector<TriangleId> ids;
  std::vector<Ray> rays;
  std::vector<StressExpect> expect;  // one per ray
  // Seam scenes: stores of the same triangles in tiny bricks and in one brick.
  std::string tiny_bricks_store;
  std::string one_brick_store;
  std::shared_ptr<StressWorkspace> workspace;
};

struct StressOptions {
  // Smaller generated meshes; models are still all used.
  bool quick = false;
  // Where fandisk.obj, homer.obj, spot.obj, beast.obj are; absent ones are
  // skipped with a note. Empty: no models.
  std::string models_dir;
  // Aim at every stride-th vertex and edge midpoint (CI under sanitizers).
  uint32_t stride = 1;
};

struct StressScenes {
  std::vector<StressScene> scenes;
  std::vector<std::string> notes;  // skipped models and variants, and why
};

Expected<StressScenes> make_stress_scenes(const StressOptions& options);

// Whether p is inside the closed mesh by float64 ray parity: odd crossing
// counts along three fixed skew directions.
bool inside_by_parity(const std::vector<Triangle>& triangles, const Vec3f& p);

}  // namespace outcore
