#include "core/gen/city_generator.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include "core/io/file_source.h"
#include "core/util/cancellation.h"

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
  p.real("tilt", c.tilt_degrees, RealRange::closed(-90.0, 90.0));
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

Expected<std::unique_ptr<CityGenerator>> CityGenerator::create(const GenSpec& spec,
                                                               const GeneratorOptions& options) {
  OUTCORE_ASSIGN_OR_RETURN(const CityConfig config, CityConfig::parse(spec));
  const std::string where = "gen:city: parameter 'of'";
  const auto too_many = [&](uint64_t base_count) {
    return invalid_argument("gen:city: parameter 'copies' = " + std::to_string(config.copies) + " times " +
                            std::to_string(base_count) + " base triangles exceeds the " +
                            std::to_string(kMaxGeneratedTriangles) +
                            " primitive ids of one input; use fewer copies or a smaller base");
  };
  const uint64_t limit = options.mesh_memory_bytes;
  const auto mib = [](uint64_t bytes) { return std::to_string((bytes + (1 << 20) - 1) >> 20) + " MiB"; };
  const auto too_large = [&](const std::string& needs) {
    return resource_exhausted(
        "gen:city: the base mesh '" + config.of + "' needs " + needs + " in memory, more than the " +
        mib(limit) + " allowed for it" +
        (options.mesh_memory_origin.empty() ? "" : " (" + options.mesh_memory_origin + ")") +
        "; use a smaller base or allow more memory");
  };

  // A nested generator gets the same limit (a city of cities holds both bases
  // while the outer one is read).
  auto opened =
      config.of.starts_with("gen:") ? make_generator(config.of, options) : open_triangle_file(config.of);
  if (!opened.ok()) return opened.status().with_context(where);
  std::unique_ptr<TriangleSource> source = std::move(opened).value();

  IndexedMeshBuilder builder;
  uint64_t expected = 0;  // 0: not known before reading
  if (const auto* gen = dynamic_cast<const Generator*>(source.get())) {
    // Known count: check the id budget and the memory before reading (a base
    // too large to hold would otherwise take minutes and gigabytes to find
    // out), and allocate exactly.
    expected = gen->triangle_count();
    if (expected != 0 && static_cast<uint64_t>(config.copies) > kMaxGeneratedTriangles / expected) {
      return too_many(expected);
    }
    const uint64_t index_bytes = expected * sizeof(std::array<uint32_t, 3>);
    if (limit != 0 && index_bytes > limit) {
      return too_large("at least " + mib(index_bytes) + " (" + std::to_string(expected) +
                       " triangles x 12 B, before its vertices)");
    }
    builder.reserve_triangles(expected);
  }
  std::size_t read = 0;
  Status stopped;  // the sink's own verdicts, returned without the stream's context
  CallbackSink sink([&](std::span<const Triangle> batch) {
    if (cancel_requested()) {
      stopped = cancelled("gen:city: interrupted while reading the base mesh '" + config.of + "'");
      return stopped;
    }
    for (const Triangle& t : batch) {
      if (!t.is_finite()) {
        return invalid_argument("triangle " + std::to_string(read) + " has a non-finite vertex");
      }
      OUTCORE_RETURN_IF_ERROR(builder.add(t));
      ++read;
    }
    if (limit != 0 && builder.memory_bytes() > limit) {
      stopped = too_large("more than " + mib(limit) + " (" + mib(builder.memory_bytes()) + " after " +
                          std::to_string(read) + (expected != 0 ? " of " + std::to_string(expected) : "") +
                          " triangles)");
      return stopped;
    }
    return Status::Ok();
  });
  if (Status s = source->stream(sink); !s.ok()) {
    if (!stopped.ok()) return stopped;
    return s.with_context(where + " ('" + config.of + "')");
  }
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
  if (config_.tilt_degrees != 0) {
    const double tilt = config_.tilt_degrees * std::numbers::pi / 180.0;
    t.tilted = true;
    t.tc = std::cos(tilt);
    t.ts = std::sin(tilt);
  }
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
  std::vector<Vec3f> world;
  for (uint64_t copy = first / base_count; copy * base_count < last; ++copy) {
    const CopyTransform t = copy_transform(static_cast<int64_t>(copy));
    const uint64_t begin = std::max(first, copy * base_count) - copy * base_count;
    const uint64_t end = std::min(last, (copy + 1) * base_count) - copy * base_count;
    // A range of a small part of a huge base transforms its own corners:
    // transforming every base vertex would cost time and scratch memory in
    // proportion to the base for every such range.
    if (3 * (end - begin) < base_.vertices.size()) {
      for (uint64_t k = begin; k < end; ++k) {
        const auto& tri = base_.triangles[k];
        OUTCORE_RETURN_IF_ERROR(
            out.add(Triangle{t.apply(base_.vertices[tri[0]]), t.apply(base_.vertices[tri[1]]),
                             t.apply(base_.vertices[tri[2]])}));
      }
      continue;
    }
    world.resize(base_.vertices.size());
    for (std::size_t i = 0; i < world.size(); ++i) world[i] = t.apply(base_.vertices[i]);
    for (uint64_t k = begin; k < end; ++k) {
      const auto& tri = base_.triangles[k];
      OUTCORE_RETURN_IF_ERROR(out.add(Triangle{world[tri[0]], world[tri[1]], world[tri[2]]}));
    }
  }
  return Status::Ok();
}

}  // namespace outcore
