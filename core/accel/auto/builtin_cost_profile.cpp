// The cost profile used when no file is given or found: `outcore calibrate`
// on the project's reference machine (2 cores, Debian 12; docs/AUTO.md).
#include "core/accel/auto/cost_profile.h"

#include <cstdlib>

namespace outcore {
namespace {

constexpr const char* kBuiltinProfile = R"(# outcore cost profile, version 1
# machine: the project's reference machine (2 cores, Debian 12), 12 samples of built-in scenes, 2026-12-06
features constant log2_triangles density_spread flatness log2_area_ratio
build bvh -16.5195118 0.0977056558 0.177960821 -0.0197516406 0.118388631
trace bvh -16.2291262 0.0777883348 -0.0908285373 -0.048427464 0.230406224
build kdtree -12.8798612 -0.0155954332 -0.00451520163 0.576009241 0.455652367
trace kdtree -14.6569616 0.118180278 -0.36574943 -0.0586091247 -0.0400324295
build bsp -6.95840465 -0.263710385 -0.0828613465 -0.374466893 1.14281088
trace bsp -14.5093955 0.105455536 -0.194852349 -0.231440247 -0.00333013314
build grid -14.6889056 -0.0400344741 -0.13734192 -0.459091945 0.14526106
trace grid -15.4486142 0.154893544 -0.0952135814 -0.230840785 -0.378676801
build hgrid -13.5760157 -0.0174447116 -0.0673667703 -0.172372815 -0.0720441524
trace hgrid -14.2519833 0.0724588262 -0.18437513 -0.224545977 -0.129098642
build octree -13.1626792 0.000829508005 -0.247328389 -0.475882757 -0.19799186
trace octree -13.9075927 0.163449819 -0.431253213 -1.30116666 -0.0681710576
build quadtree -15.8116327 0.153382947 -0.328094906 -0.36671656 0.124696988
trace quadtree -14.2650254 0.068179383 -0.152410082 -0.0634776003 0.165685119
)";

}  // namespace

const CostProfile& builtin_cost_profile() {
  static const CostProfile profile = [] {
    Expected<CostProfile> parsed = parse_cost_profile(kBuiltinProfile, "built-in");
    if (!parsed.ok()) std::abort();  // a build-time constant: the tests read it
    return std::move(parsed).value();
  }();
  return profile;
}

}  // namespace outcore
