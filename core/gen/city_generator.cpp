#include "core/gen/city_generator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "core/io/source_factory.h"

#include "core/gen/splitmix.h"

namespace outcore {

namespace {

constexpr uint64_t kGolden = 0x9e3779b97f4a7c15ull;

// Counter-based random numbers: the k-th draw of copy c depends on (seed, c, k) only.
class CopyRandom {
 public:
  CopyRandom(int64_t seed, int64_t copy)
      : state_(mix64(mix64(static_cast<uint64_t>(seed) ^ 0x63697479ull) +
                     static_cast<uint64_t>(copy) * kGolden)) {}
  double uniform() {  // [0, 1)
    state_ += kGolden;
    return static_cast<double>(mix64(state_) >> 11) * (1.0 / 9007199254740992.0);
  }

 private:
  uint64_t state_;
};

constexpr double kJitter = 0.15;   // max x/z offset from the cell centre, in cells
constexpr double kYOffset = 0.05;  // max |y offset|, in base diagonals

}  // namespace

Expected<CityConfig> CityConfig::parse(const GenSpec& spec) {
  CityConfig c;
  GenParams p(spec);
  p.text("of", c.of);
  p.integer("copies", c.copies, 1, kMaxCopies);
  p.integer("seed", c.seed, 0, std::numeric_limits<int64_t>::max());
  p.real("spacing", c.spacing, RealRange::positive());
  OUTCORE_RETURN_IF_ERROR(p.finish());
  return c;
}

CityGenerator::CityGenerator(std::string description, const CityConfig& config, IndexedMesh base)
    : Generator(std::move(description)), config_(config), base_(std::move(base)) {
  const Aabb box = base_.bounds();
  centre_ = (Vec3d(box.lo) + Vec3d(box.hi)) * 0.5;
  diagonal_ = length(Vec3d(box.hi) - Vec3d(box.lo));
  cell_ = config_.spacing ? *config_.spacing : 2.5 * diagonal_;
  side_ = static_cast<int64_t>(std::sqrt(static_cast<double>(config_.copies)));
  while (side_ * side_ < config_.copies) ++side_;
  while (side_ > 1 && (side_ - 1) * (side_ - 1) >= config_.copies) --side_;
}

Expected<std::unique_ptr<CityGenerator>> CityGenerator::create(const GenSpec& spec) {
  OUTCORE_ASSIGN_OR_RETURN(const CityConfig config, CityConfig::parse(spec));
  const std::string where = "gen:city: parameter 'of'";
  const auto too_many = [&](uint64_t base_count) {
    return invalid_argument("gen:city: parameter 'copies' = " + std::to_string(config.copies) + " times " +
                            std::to_string(base_count) + " base triangles exceeds the " +
                            std::to_string(kMaxGeneratedTriangles) +
                            " primitive ids of one input; use fewer copies or a smaller base");
  };

  auto opened = open_triangle_source(config.of);
  if (!opened.ok()) return opened.status().with_context(where);
  std::unique_ptr<TriangleSource> source = std::move(opened).value();

  IndexedMeshBuilder builder;
  if (const auto* gen = dynamic_cast<const Generator*>(source.get())) {
    // Known count: check the id budget before reading, and allocate exactly.
    const uint64_t count = gen->triangle_count();
    if (count != 0 && static_cast<uint64_t>(config.copies) > kMaxGeneratedTriangles / count) {
      return too_many(count);
    }
    builder.reserve_triangles(count);
  }
  std::size_t read = 0;
  CallbackSink sink([&](std::span<const Triangle> batch) {
    for (const Triangle& t : batch) {
      if (!t.is_finite()) {
        return invalid_argument("triangle " + std::to_string(read) + " has a non-finite vertex");
      }
      OUTCORE_RETURN_IF_ERROR(builder.add(t));
      ++read;
    }
    return Status::Ok();
  });
  if (Status s = source->stream(sink); !s.ok()) return s.with_context(where + " ('" + config.of + "')");
  IndexedMesh base = builder.finish();

  if (base.triangle_count() == 0) return invalid_argument(where + ": '" + config.of + "' has no triangles");
  if (static_cast<uint64_t>(config.copies) > kMaxGeneratedTriangles / base.triangle_count()) {
    return too_many(base.triangle_count());
  }

  std::unique_ptr<CityGenerator> city(new CityGenerator(spec.text, config, std::move(base)));
  if (!(city->cell_ > 0.0)) {
    return invalid_argument("gen:city: parameter 'spacing' is required: the base mesh '" + config.of +
                            "' has a zero-size bounding box");
  }
  return city;
}

CopyTransform CityGenerator::copy_transform(int64_t copy) const {
  CopyRandom rng(config_.seed, copy);
  const double angle = 2.0 * std::numbers::pi * rng.uniform();
  const double scale = 0.5 + rng.uniform();
  const double jx = (2.0 * rng.uniform() - 1.0) * kJitter * cell_;
  const double jz = (2.0 * rng.uniform() - 1.0) * kJitter * cell_;
  const double dy = (2.0 * rng.uniform() - 1.0) * kYOffset * diagonal_;

  const int64_t col = copy % side_;
  const int64_t row = copy / side_;
  const double half = 0.5 * static_cast<double>(side_);
  const Vec3d place((static_cast<double>(col) + 0.5 - half) * cell_ + jx, centre_.y + dy,
                    (static_cast<double>(row) + 0.5 - half) * cell_ + jz);

  CopyTransform t;
  t.sc = std::cos(angle) * scale;
  t.ss = std::sin(angle) * scale;
  t.scale = scale;
  // p -> M (p - centre) + place  ==  M p + (place - M centre)
  t.t = Vec3d(place.x - (t.sc * centre_.x + t.ss * centre_.z), place.y - scale * centre_.y,
              place.z - (t.sc * centre_.z - t.ss * centre_.x));
  return t;
}

Status CityGenerator::emit(TriangleBatcher& out) const {
  return emit_range(0, triangle_count(), out);
}

Status CityGenerator::emit_range(uint64_t first, uint64_t last, TriangleBatcher& out) const {
  last = std::min(last, triangle_count());
  if (first >= last) return Status::Ok();
  // The current copy's vertices: each unique base vertex is transformed once
  // per copy, and the transform is a pure function of the vertex, so this is
  // bit-identical to transforming every triangle corner.
  const uint64_t base_count = base_.triangle_count();
  std::vector<Vec3f> world(base_.vertices.size());
  for (uint64_t copy = first / base_count; copy * base_count < last; ++copy) {
    const CopyTransform t = copy_transform(static_cast<int64_t>(copy));
    for (std::size_t i = 0; i < world.size(); ++i) world[i] = t.apply(base_.vertices[i]);
    const uint64_t begin = std::max(first, copy * base_count) - copy * base_count;
    const uint64_t end = std::min(last, (copy + 1) * base_count) - copy * base_count;
    for (uint64_t k = begin; k < end; ++k) {
      const auto& tri = base_.triangles[k];
      OUTCORE_RETURN_IF_ERROR(out.add(Triangle{world[tri[0]], world[tri[1]], world[tri[2]]}));
    }
  }
  return Status::Ok();
}

}  // namespace outcore
