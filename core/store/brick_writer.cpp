#include "core/store/brick_writer.h"

#include <cstring>

#include "core/store/store_format.h"
#include "core/util/checksum.h"

namespace outcore::packing {

Status BrickWriter::create(const std::string& path, uint64_t buffer_bytes, uint64_t staging_bytes,
                           uint64_t triangles, bool show_progress) {
  OUTCORE_RETURN_IF_ERROR(file_.create(path, buffer_bytes, /*asynchronous=*/true));
  staging_.resize(staging_bytes);
  progress_ = std::make_unique<ProgressBar>("bricks", triangles, "tris", show_progress);
  return Status::Ok();
}

Status BrickWriter::write(std::span<const PackedTriangle> triangles, const Aabb& bounds) {
  OUTCORE_RETURN_IF_ERROR(file_.pad_to(kBrickAlignment));
  BrickRecord record;
  record.bounds = bounds;
  bound_scratch_.clear();
  for (const PackedTriangle& p : triangles) bound_scratch_.push_back(p.tri);
  record.sphere = BoundingSphere::fit(bound_scratch_);
  record.obb = OrientedBox::fit(bound_scratch_);
  record.triangle_count = static_cast<uint32_t>(triangles.size());
  record.offset = file_.size();
  record.size_bytes = brick_total_bytes(triangles.size());
  BrickHeader header{};
  std::memcpy(header.magic, kBrickMagic, sizeof header.magic);
  header.brick_id = static_cast<uint32_t>(bricks_.size());
  header.triangle_count = record.triangle_count;
  header.payload_bytes = brick_payload_bytes(triangles.size());
  Checksum64 checksum;
  checksum.update(&header, sizeof header);
  OUTCORE_RETURN_IF_ERROR(file_.append(&header, sizeof header));
  // Positions, then ids, staged through a fixed buffer so the checksum and the
  // write see large contiguous pieces.
  auto emit = [&](auto&& field_bytes, std::size_t record_bytes) -> Status {
    std::size_t used = 0;
    for (const PackedTriangle& p : triangles) {
      if (used + record_bytes > staging_.size()) {
        checksum.update(staging_.data(), used);
        OUTCORE_RETURN_IF_ERROR(file_.append(staging_.data(), used));
        used = 0;
      }
      field_bytes(p, staging_.data() + used);
      used += record_bytes;
    }
    checksum.update(staging_.data(), used);
    return file_.append(staging_.data(), used);
  };
  OUTCORE_RETURN_IF_ERROR(
      emit([](const PackedTriangle& p, char* out) { std::memcpy(out, &p.tri, sizeof(Triangle)); },
           sizeof(Triangle)));
  OUTCORE_RETURN_IF_ERROR(emit(
      [](const PackedTriangle& p, char* out) {
        std::memcpy(out, &p.geometry_id, sizeof(uint32_t));
        std::memcpy(out + sizeof(uint32_t), &p.primitive_id, sizeof(uint32_t));
      },
      2 * sizeof(uint32_t)));
  record.checksum = checksum.digest();
  bricks_.push_back(record);
  if (progress_) progress_->advance(triangles.size());
  return Status::Ok();
}

Status BrickWriter::close(bool sync) {
  if (progress_) progress_->finish();
  return file_.close(sync);
}

}  // namespace outcore::packing
