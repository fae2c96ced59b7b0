// The cost profile used when no file is given or found: `outcore calibrate`
// on the project's reference machine (2 cores, Debian 12; docs/AUTO.md).
#include "core/accel/auto/cost_profile.h"

#include <cstdlib>

namespace outcore {
namespace {

constexpr const char* kBuiltinProfile = R"(# outcore cost profile, version 1
# machine: the project's reference machine (2 cores, Debian 12), 12 samples of built-in scenes, 2026-12-06
# build bvh: remeasured 2026-12-07 after the builder moved its triangles in place (calibrate --structures bvh)
features constant log2_triangles density_spread flatness log2_area_ratio
build bvh -16.9179275 0.102707002 -0.0501864094 0.341362126 0.0852131248
trace bvh -16.189234 0.0720134429 -0.105692457 -0.0876194107 0.223275315
build kdtree -12.9343334 -0.0137656583 -0.0227752985 0.516445737 0.522306647
trace kdtree -14.691741 0.117293657 -0.379777656 -0.100072368 0.0215038879
build bsp -6.98553729 -0.268135008 -0.0991037176 -0.348410308 1.14163301
trace bsp -14.682269 0.108898379 -0.226974565 -0.154537116 0.000958322661
build grid -14.9288449 -0.0337880559 -0.176266001 -0.339352505 0.131592296
trace grid -15.6810209 0.159525987 -0.112630917 -0.109980791 -0.376973863
build hgrid -13.6844858 -0.0185634967 -0.107366609 -0.0664035944 -0.130550463
trace hgrid -14.3373287 0.0695935674 -0.214110796 -0.166708721 -0.162814264
build octree -13.2414196 -0.00178283582 -0.275632136 -0.421270685 -0.240482645
trace octree -14.0083876 0.155185669 -0.391190548 -1.22346561 -0.0315668686
build quadtree -15.8058034 0.134253686 -0.286319581 -0.204773901 0.135958625
trace quadtree -14.3859245 0.0609599897 -0.116147336 0.0123033418 0.196457057
# the measured bricks: triangles density_spread flatness area_ratio
sample 80 0.678071905 1 0.486080472
sample 1280 0.584962501 1 0.521103858
sample 20480 0.50779464 1 0.523442228
sample 327680 0.487639087 1 0.523588989
sample 4096 1.0768156 0.2 0.562506824
sample 1800 1.45300535 0.127903295 0.433307638
sample 80000 1.3556929 0.0387667704 0.470872357
sample 2048 3.52356196 0.25 0.666667709
sample 82688 3.997765 0.25 0.666667714
sample 4000 1.40925515 0.0976828041 0.284934324
sample 51200 1.27500705 0.148713502 0.516989893
sample 69120 2.11855661 0.489981479 0.109442925
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
