#include "core/accel/auto/auto_brick_serializer.h"

#include <cmath>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "core/accel/auto/auto_brick.h"

namespace outcore {
namespace {

constexpr uint32_t kMagic = 0x3141434fu;  // "OCA1" little-endian
constexpr std::size_t kHeaderBytes = 64;

struct AutoPayloadHeader {
  uint32_t magic = kMagic;
  uint32_t candidate = 0;
  uint64_t inner_bytes = 0;
  double density_spread = 0;
  double flatness = 0;
  double area_ratio = 0;
  char zero[24] = {};
};
static_assert(sizeof(AutoPayloadHeader) == kHeaderBytes);

class AutoBrickSerializer final : public BrickSerializer {
 public:
  explicit AutoBrickSerializer(std::vector<const BrickSerializer*> inner) : inner_(std::move(inner)) {
    key_ = "auto/1 [";
    for (std::size_t c = 0; c < inner_.size(); ++c) key_ += (c ? "; " : "") + inner_[c]->structure_key();
    key_ += "]";
  }

  const std::string& structure_key() const override { return key_; }

  Status save(const BrickAccel& accel, std::ostream& out) const override {
    const auto* built = dynamic_cast<const AutoBrickAccel*>(&accel);
    if (built == nullptr || built->candidate() >= inner_.size())
      return invalid_argument("auto serialiser: the brick was not built by the auto builder");
    std::ostringstream inner;
    OUTCORE_RETURN_IF_ERROR(inner_[built->candidate()]->save(built->inner(), inner));
    const std::string bytes = inner.str();
    AutoPayloadHeader header;
    header.candidate = built->candidate();
    header.inner_bytes = bytes.size();
    header.density_spread = built->features().density_spread;
    header.flatness = built->features().flatness;
    header.area_ratio = built->features().area_ratio;
    out.write(reinterpret_cast<const char*>(&header), sizeof(header));
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) return io_error("auto serialiser: writing brick payload failed");
    return Status::Ok();
  }

  Expected<std::unique_ptr<BrickAccel>> load(const SerializedBrick& payload, uint32_t brick_id,
                                             uint32_t triangle_count) const override {
    const std::string what = "auto payload of brick " + std::to_string(brick_id);
    if (payload.bytes.size() < kHeaderBytes) {
      return invalid_argument(what + ": truncated (" + std::to_string(payload.bytes.size()) +
                              " bytes, no header)");
    }
    AutoPayloadHeader header;
    std::memcpy(&header, payload.bytes.data(), sizeof(header));
    if (header.magic != kMagic) return invalid_argument(what + ": bad magic");
    if (header.candidate >= inner_.size()) {
      return invalid_argument(what + ": candidate " + std::to_string(header.candidate) + " of " +
                              std::to_string(inner_.size()));
    }
    if (header.inner_bytes != payload.bytes.size() - kHeaderBytes) {
      return invalid_argument(what + ": says " + std::to_string(header.inner_bytes) + " payload bytes, has " +
                              std::to_string(payload.bytes.size() - kHeaderBytes));
    }
    BrickFeatures features;
    features.triangles = triangle_count;
    features.density_spread = header.density_spread;
    features.flatness = header.flatness;
    features.area_ratio = header.area_ratio;
    const bool features_valid = std::isfinite(features.density_spread) && features.density_spread >= 0 &&
                                features.density_spread <= 6.5 && features.flatness >= 0 &&
                                features.flatness <= 1 && std::isfinite(features.area_ratio) &&
                                features.area_ratio >= 0;
    if (!features_valid) return invalid_argument(what + ": brick features out of range");
    SerializedBrick inner = payload;
    inner.bytes = payload.bytes.subspan(kHeaderBytes);
    OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<BrickAccel> accel,
                             inner_[header.candidate]->load(inner, brick_id, triangle_count));
    return std::unique_ptr<BrickAccel>(new AutoBrickAccel(std::move(accel), header.candidate, features));
  }

 private:
  std::vector<const BrickSerializer*> inner_;
  std::string key_;
};

}  // namespace

std::unique_ptr<BrickSerializer> make_auto_brick_serializer(const AutoBrickBuilder& builder) {
  std::vector<const BrickSerializer*> inner;
  for (uint32_t c = 0; c < builder.candidates().size(); ++c) {
    const BrickSerializer* serializer = builder.candidate_builder(c).serializer();
    if (serializer == nullptr) return nullptr;
    inner.push_back(serializer);
  }
  return std::make_unique<AutoBrickSerializer>(std::move(inner));
}

}  // namespace outcore
