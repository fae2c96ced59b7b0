#include "core/store/manifest.h"

#include <cereal/archives/portable_binary.hpp>
#include <cereal/types/string.hpp>
#include <cereal/types/vector.hpp>

#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/store/store_format.h"
#include "core/upper/upper_traversal.h"
#include "core/util/checksum.h"

namespace outcore {

Status write_manifest(const std::string& path, const Manifest& manifest) {
  std::ostringstream payload_stream;
  {
    cereal::PortableBinaryOutputArchive archive(payload_stream);
    archive(manifest);
  }
  const std::string payload = std::move(payload_stream).str();
  StoreFileHeader header{};
  std::memcpy(header.magic, kManifestMagic, sizeof header.magic);
  header.format_version = kStoreFormatVersion;
  header.header_bytes = sizeof(StoreFileHeader);
  header.payload_bytes = payload.size();
  header.payload_checksum = checksum64(payload.data(), payload.size());

  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return io_error_from_errno("cannot create " + path);
  out.write(reinterpret_cast<const char*>(&header), sizeof header);
  out.write(payload.data(), static_cast<std::streamsize>(payload.size()));
  out.flush();
  if (!out) return io_error_from_errno("cannot write " + path);
  return Status::Ok();
}

Expected<Manifest> read_manifest(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return io_error_from_errno("cannot open manifest " + path);
  in.seekg(0, std::ios::end);
  const auto file_bytes = static_cast<uint64_t>(in.tellg());
  in.seekg(0);
  StoreFileHeader header{};
  if (file_bytes < sizeof header) {
    return data_loss("manifest " + path + " is truncated (" + std::to_string(file_bytes) +
                     " bytes, header alone is " + std::to_string(sizeof header) + ")");
  }
  in.read(reinterpret_cast<char*>(&header), sizeof header);
  if (std::memcmp(header.magic, kManifestMagic, sizeof header.magic) != 0) {
    return invalid_argument(path + " is not an Outcore scene store manifest (bad magic)");
  }
  if (header.format_version != kStoreFormatVersion) {
    return failed_precondition("scene store " + path + " has format version " +
                               std::to_string(header.format_version) +
                               "; this outcore reads format version " + std::to_string(kStoreFormatVersion) +
                               " (re-pack the scene with `outcore pack --force ...`: the store "
                               "holds no data that its inputs cannot give again)");
  }
  if (header.header_bytes != sizeof header) {
    return data_loss("manifest " + path + " has a malformed header (header size " +
                     std::to_string(header.header_bytes) + ")");
  }
  if (file_bytes != sizeof header + header.payload_bytes) {
    return data_loss("manifest " + path + " is " +
                     (file_bytes < sizeof header + header.payload_bytes ? "truncated" : "too long") + " (" +
                     std::to_string(file_bytes) + " bytes, expected " +
                     std::to_string(sizeof header + header.payload_bytes) + ")");
  }
  std::string payload(header.payload_bytes, '\0');
  in.read(payload.data(), static_cast<std::streamsize>(payload.size()));
  if (!in) return io_error_from_errno("cannot read manifest " + path);
  if (checksum64(payload.data(), payload.size()) != header.payload_checksum) {
    return data_loss("manifest " + path + " is corrupted (checksum mismatch)");
  }
  Manifest manifest;
  try {
    std::istringstream payload_stream(payload);
    cereal::PortableBinaryInputArchive archive(payload_stream);
    archive(manifest);
  } catch (const std::exception& e) {
    return data_loss("manifest " + path + " cannot be decoded: " + e.what());
  }
  manifest.format_version = header.format_version;
  OUTCORE_RETURN_IF_ERROR(validate_manifest(manifest, path));
  return manifest;
}

namespace {

// A brick's sphere and oriented box are finite and not empty (a brick has
// triangles); the tests never see NaN from a damaged manifest.
bool brick_bounds_are_sound(const BrickRecord& brick) {
  const BoundingSphere& s = brick.sphere;
  if (!is_finite(s.center) || !std::isfinite(s.radius) || s.empty()) return false;
  const OrientedBox& b = brick.obb;
  for (int k = 0; k < 3; ++k) {
    if (!is_finite(b.axes[k]) || !std::isfinite(b.lo[k]) || !std::isfinite(b.hi[k]) || !(b.lo[k] <= b.hi[k]))
      return false;
  }
  return true;
}

}  // namespace

Status validate_manifest(const Manifest& manifest, const std::string& path) {
  auto bad = [&](const std::string& what) { return data_loss("manifest " + path + ": " + what); };
  if (manifest.bricks.empty()) return bad("no bricks");
  uint64_t input_total = 0;
  for (const InputRecord& input : manifest.inputs) input_total += input.triangle_count;
  if (input_total != manifest.triangle_count)
    return bad("input triangle counts do not add up to the scene total");
  uint64_t brick_total = 0;
  uint64_t previous_end = 0;
  for (size_t id = 0; id < manifest.bricks.size(); ++id) {
    const BrickRecord& brick = manifest.bricks[id];
    const std::string name = "brick " + std::to_string(id);
    if (brick.triangle_count == 0) return bad(name + " is empty");
    if (brick.offset % kBrickAlignment != 0 || brick.offset < previous_end)
      return bad(name + " has a bad byte range");
    if (brick.size_bytes != brick_total_bytes(brick.triangle_count)) return bad(name + " has a bad size");
    if (!manifest.bounds.contains(brick.bounds)) return bad(name + " lies outside the scene bounds");
    if (!brick_bounds_are_sound(brick))
      return bad(name + " has a NaN, infinite or empty sphere or oriented box");
    previous_end = brick.offset + brick.size_bytes;
    brick_total += brick.triangle_count;
  }
  if (brick_total != manifest.triangle_count)
    return bad("brick triangle counts do not add up to the scene total");

  const auto& nodes = manifest.upper.nodes;
  if (nodes.size() != 2 * manifest.bricks.size() - 1)
    return bad("upper hierarchy has the wrong number of nodes");
  std::vector<uint8_t> seen(manifest.bricks.size(), 0);
  for (size_t i = 0; i < nodes.size(); ++i) {
    const UpperNode& node = nodes[i];
    if (node.is_leaf) {
      if (node.child_or_brick >= manifest.bricks.size() || seen[node.child_or_brick]++) {
        return bad("upper hierarchy leaf " + std::to_string(i) + " names a missing or repeated brick");
      }
      if (!node.bounds.contains(manifest.bricks[node.child_or_brick].bounds)) {
        return bad("upper hierarchy leaf " + std::to_string(i) + " does not contain its brick");
      }
    } else {
      // Children after their parent rules out cycles.
      if (node.child_or_brick <= i || node.child_or_brick + 1 >= nodes.size()) {
        return bad("upper hierarchy node " + std::to_string(i) + " has bad children");
      }
      if (!node.bounds.contains(nodes[node.child_or_brick].bounds) ||
          !node.bounds.contains(nodes[node.child_or_brick + 1].bounds)) {
        return bad("upper hierarchy node " + std::to_string(i) + " does not contain its children");
      }
    }
  }
  if (manifest.upper.depth() > kMaxUpperDepth) {
    return bad("upper hierarchy is deeper than " + std::to_string(kMaxUpperDepth) + " levels");
  }
  return Status::Ok();
}

}  // namespace outcore
