#include "core/accel/hgrid/hgrid_brick_serializer.h"

#include <cereal/archives/binary.hpp>

#include <cstdio>
#include <cstring>

#include "core/accel/payload_io.h"

namespace outcore {
namespace {

constexpr uint64_t kCountsOffset = 8;
constexpr uint64_t kHeaderBytes = 64;

std::string key_of(const HgridBrickConfig& config) {
  char key[256];
  std::snprintf(key, sizeof(key),
                "hgrid/%d triangle_test=%s top_cells_per_triangle=%a cells_per_triangle=%a "
                "max_cell_triangles=%u max_levels=%u",
                HgridBrickSerializer::kPayloadVersion,
                std::string(triangle_test_name(config.triangle_test)).c_str(),
                static_cast<double>(config.builder.top_cells_per_triangle),
                static_cast<double>(config.builder.cells_per_triangle), config.builder.max_cell_triangles,
                config.builder.max_levels);
  return key;
}

}  // namespace

HgridBrickSerializer::HgridBrickSerializer(const HgridBrickConfig& config)
    : test_(config.triangle_test), key_(key_of(config)) {}

Status HgridBrickSerializer::save(const BrickAccel& accel, std::ostream& out) const {
  const std::string name = "hgrid serialiser";
  OUTCORE_ASSIGN_OR_RETURN(const HgridBrickAccel* grid_accel,
                           payload_io::brick_to_save<HgridBrickAccel>(accel, test_, name, "hgrid"));
  const HierarchicalGridView grid = grid_accel->view();
  try {
    cereal::BinaryOutputArchive archive(out);
    archive(static_cast<uint8_t>(test_));
    payload_io::write_zeros(archive, kCountsOffset - 1);
    archive(static_cast<uint64_t>(grid.grids.size()), static_cast<uint64_t>(grid.cells.size()),
            static_cast<uint64_t>(grid.refs.size()), static_cast<uint64_t>(grid.triangles.size()));
    payload_io::write_zeros(archive, kHeaderBytes - kCountsOffset - 4 * sizeof(uint64_t));
    payload_io::write_array(archive, grid.grids);
    payload_io::write_array(archive, grid.cells);
    payload_io::write_array(archive, grid.refs);
    payload_io::write_array(archive, grid.triangles);
    payload_io::write_array(archive, grid.records);
  } catch (const std::exception& e) {
    return io_error(name + ": " + e.what());
  }
  if (!out) return io_error(name + ": write failed");
  return Status::Ok();
}

Expected<std::unique_ptr<BrickAccel>> HgridBrickSerializer::load(const SerializedBrick& payload,
                                                                 uint32_t brick_id,
                                                                 uint32_t triangle_count) const {
  const std::string what = "hgrid serialiser: brick " + std::to_string(brick_id);
  const std::span<const char> bytes = payload.bytes;
  OUTCORE_RETURN_IF_ERROR(payload_io::check_header(bytes, kHeaderBytes, test_, what));
  uint64_t counts[4];  // grids, cells, references, triangles
  std::memcpy(counts, bytes.data() + kCountsOffset, sizeof(counts));
  // The builder's budgets: a payload cannot claim more than a build of this
  // brick could have made.
  const uint64_t n = triangle_count;
  if (counts[3] > n) {
    return invalid_argument(what + ": " + std::to_string(counts[3]) + " triangles, more than the brick's " +
                            std::to_string(n));
  }
  if (counts[0] > HierarchicalGridBuilder::grids_cap(n) ||
      counts[1] > HierarchicalGridBuilder::cells_cap(n) ||
      counts[2] > HierarchicalGridBuilder::references_cap(n)) {
    return invalid_argument(what + ": " + std::to_string(counts[0]) + " grids, " + std::to_string(counts[1]) +
                            " cells and " + std::to_string(counts[2]) + " references, more than a grid of " +
                            std::to_string(n) + " triangles holds");
  }
  const uint64_t cells_at = kHeaderBytes + counts[0] * sizeof(HgridGrid);
  const uint64_t refs_at = cells_at + counts[1] * sizeof(HgridCell);
  const uint64_t triangles_at = refs_at + counts[2] * sizeof(uint32_t);
  const uint64_t records_at = triangles_at + counts[3] * sizeof(Triangle);
  const uint64_t end = records_at + counts[3] * sizeof(BvhHitRecord);
  if (end != bytes.size()) {
    return invalid_argument(what + ": " + std::to_string(bytes.size()) + " bytes, the grid's counts need " +
                            std::to_string(end));
  }
  HierarchicalGrid grid;
  payload_io::read_array(grid.grids, counts[0], bytes, kHeaderBytes);
  payload_io::read_array(grid.cells, counts[1], bytes, cells_at);
  payload_io::read_array(grid.refs, counts[2], bytes, refs_at);
  payload_io::read_array(grid.triangles, counts[3], bytes, triangles_at);
  payload_io::read_array(grid.records, counts[3], bytes, records_at);
  if (!payload.known_good) {
    for (const HgridGrid& g : grid.grids) {
      if (g.unused != 0) return invalid_argument(what + ": a grid's padding is not zero");
    }
    const Status valid = grid.view().validate();
    if (!valid.ok()) return invalid_argument(what + ": " + valid.message());
  }
  return std::unique_ptr<BrickAccel>(
      HgridBrickAccel::from_tree(std::move(grid), test_, brick_id, triangle_count));
}

}  // namespace outcore
