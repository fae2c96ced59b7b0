#include "core/accel/grid/grid_brick_serializer.h"

#include <cereal/archives/binary.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "core/accel/payload_io.h"

namespace outcore {
namespace {

constexpr uint64_t kCountsOffset = 8;
constexpr uint64_t kResolutionOffset = 32;
constexpr uint64_t kGeometryOffset = 48;
constexpr uint64_t kHeaderBytes = 96;

std::string key_of(const GridBrickConfig& config) {
  char key[256];
  std::snprintf(
      key, sizeof(key), "grid/%d triangle_test=%s resolution=%s cells_per_triangle=%a max_resolution=%u",
      GridBrickSerializer::kPayloadVersion, std::string(triangle_test_name(config.triangle_test)).c_str(),
      std::string(resolution_rule_name(config.builder.rule)).c_str(),
      static_cast<double>(config.builder.cells_per_triangle), config.builder.max_resolution);
  return key;
}

}  // namespace

GridBrickSerializer::GridBrickSerializer(const GridBrickConfig& config)
    : test_(config.triangle_test), key_(key_of(config)) {}

Status GridBrickSerializer::save(const BrickAccel& accel, std::ostream& out) const {
  const std::string name = "grid serialiser";
  OUTCORE_ASSIGN_OR_RETURN(const GridBrickAccel* grid_accel,
                           payload_io::brick_to_save<GridBrickAccel>(accel, test_, name, "grid"));
  const UniformGridView grid = grid_accel->view();
  try {
    cereal::BinaryOutputArchive archive(out);
    archive(static_cast<uint8_t>(test_));
    payload_io::write_zeros(archive, kCountsOffset - 1);
    archive(static_cast<uint64_t>(grid.cell_starts.empty() ? 0 : grid.cell_count()),
            static_cast<uint64_t>(grid.refs.size()), static_cast<uint64_t>(grid.triangles.size()));
    archive(grid.resolution[0], grid.resolution[1], grid.resolution[2]);
    payload_io::write_zeros(archive, kGeometryOffset - kResolutionOffset - 12);
    const std::array<float, 9> geometry{grid.bounds.lo.x,  grid.bounds.lo.y,  grid.bounds.lo.z,
                                        grid.bounds.hi.x,  grid.bounds.hi.y,  grid.bounds.hi.z,
                                        grid.cell_width.x, grid.cell_width.y, grid.cell_width.z};
    archive(cereal::binary_data(geometry.data(), sizeof(geometry)));
    payload_io::write_zeros(archive, kHeaderBytes - kGeometryOffset - sizeof(geometry));
    payload_io::write_array(archive, grid.cell_starts);
    payload_io::write_array(archive, grid.refs);
    payload_io::write_array(archive, grid.triangles);
    payload_io::write_array(archive, grid.records);
  } catch (const std::exception& e) {
    return io_error(name + ": " + e.what());
  }
  if (!out) return io_error(name + ": write failed");
  return Status::Ok();
}

Expected<std::unique_ptr<BrickAccel>> GridBrickSerializer::load(const SerializedBrick& payload,
                                                                uint32_t brick_id,
                                                                uint32_t triangle_count) const {
  const std::string what = "grid serialiser: brick " + std::to_string(brick_id);
  const std::span<const char> bytes = payload.bytes;
  OUTCORE_RETURN_IF_ERROR(payload_io::check_header(bytes, kHeaderBytes, test_, what));
  uint64_t counts[3];
  std::memcpy(counts, bytes.data() + kCountsOffset, sizeof(counts));
  UniformGrid grid;
  std::memcpy(grid.resolution.data(), bytes.data() + kResolutionOffset, sizeof(grid.resolution));
  // The builder's budgets: a payload cannot claim more than a build of this
  // brick could have made.
  const uint64_t n = triangle_count;
  const uint64_t max_cells = UniformGridBuilder::kMaxCellsPerTriangle * n + 4096;
  const uint64_t max_refs = UniformGridBuilder::kMaxReferencesPerTriangle * n + 64;
  if (counts[2] > n) {
    return invalid_argument(what + ": " + std::to_string(counts[2]) + " triangles, more than the brick's " +
                            std::to_string(n));
  }
  if (counts[0] > max_cells || counts[1] > max_refs) {
    return invalid_argument(what + ": " + std::to_string(counts[0]) + " cells and " +
                            std::to_string(counts[1]) + " references, more than a grid of " +
                            std::to_string(n) + " triangles holds");
  }
  const uint64_t starts = counts[0] == 0 ? 0 : counts[0] + 1;
  const uint64_t refs_at = kHeaderBytes + starts * sizeof(uint32_t);
  const uint64_t triangles_at = refs_at + counts[1] * sizeof(uint32_t);
  const uint64_t records_at = triangles_at + counts[2] * sizeof(Triangle);
  const uint64_t end = records_at + counts[2] * sizeof(BvhHitRecord);
  if (end != bytes.size()) {
    return invalid_argument(what + ": " + std::to_string(bytes.size()) + " bytes, the grid's counts need " +
                            std::to_string(end));
  }
  float geometry[9];
  std::memcpy(geometry, bytes.data() + kGeometryOffset, sizeof(geometry));
  grid.bounds.lo = {geometry[0], geometry[1], geometry[2]};
  grid.bounds.hi = {geometry[3], geometry[4], geometry[5]};
  grid.cell_width = {geometry[6], geometry[7], geometry[8]};
  payload_io::read_array(grid.cell_starts, starts, bytes, kHeaderBytes);
  payload_io::read_array(grid.refs, counts[1], bytes, refs_at);
  payload_io::read_array(grid.triangles, counts[2], bytes, triangles_at);
  payload_io::read_array(grid.records, counts[2], bytes, records_at);
  if (!payload.known_good) {
    if (counts[0] != 0 && counts[0] != grid.view().cell_count()) {
      return invalid_argument(what + ": " + std::to_string(counts[0]) + " cells, the resolution makes " +
                              std::to_string(grid.view().cell_count()));
    }
    const Status valid = grid.view().validate();
    if (!valid.ok()) return invalid_argument(what + ": " + valid.message());
  }
  return std::unique_ptr<BrickAccel>(
      GridBrickAccel::from_tree(std::move(grid), test_, brick_id, triangle_count));
}

}  // namespace outcore
