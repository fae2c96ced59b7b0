// proxies.bin: the store's cached occupancy proxies (proxy_set.h), beside
// manifest.bin and bricks.dat. Written by the engine on first open, never by
// the packer; a rebuildable cache, so any mismatch means "rebuild", never
// "refuse the store". Layout (little-endian):
//   ProxyFileHeader (magic "OCPROXY\x1a", format version, resolution, margin,
//                    brick count, store fingerprint, totals, payload size and
//                    XXH3-64 of the payload)
//   per brick: frame (origin_WS 3 x f64, voxel_size_WS f64, dims_IS 3 x i32,
//              pad, margin_WS f64), leaf count u32, pad u32, then per 8^3
//              leaf: origin 3 x i32, pad, 8 x u64 occupancy words (bit
//              x*64 + y*8 + z, OpenVDB's leaf offset order).
// A reader recomputes every brick's frame from the manifest and requires the
// stored one to match bit for bit, and every leaf to lie inside its domain.
//
// Thread-safety: plain functions; writers never touch the final file until
// the rename.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/proxy/proxy_set.h"
#include "core/store/manifest.h"
#include "core/store/store_format.h"
#include "core/util/status.h"

namespace outcore {

// 2: margins grown with the scene's reach (proxy_builder.h); 1 files are rebuilt.
inline constexpr uint32_t kProxyFormatVersion = 2;
inline constexpr char kProxyMagic[8] = {'O', 'C', 'P', 'R', 'O', 'X', 'Y', '\x1a'};

struct ProxyFileHeader {
  char magic[8];
  uint32_t format_version;
  uint32_t header_bytes;  // sizeof(ProxyFileHeader)
  uint32_t resolution;
  uint32_t brick_count;
  double margin_voxels;
  uint64_t store_fingerprint;
  uint64_t active_voxels;
  uint64_t memory_bytes;  // resident bytes of the set when written
  uint64_t payload_bytes;
  uint64_t payload_checksum;  // XXH3-64 of the payload
};
static_assert(sizeof(ProxyFileHeader) == 72);

// XXH3-64 over the brick count and every brick's bounds, triangle count and
// checksum: proxies.bin belongs to the store it was built for.
uint64_t store_fingerprint(const Manifest& manifest);

// Writes `directory`/proxies.bin atomically (temporary file, fsync, rename).
Status write_proxy_file(const std::string& directory, const ProxySet& set, uint64_t fingerprint);

// Reads and checks a proxies.bin for this manifest and configuration:
// NOT_FOUND when missing; FAILED_PRECONDITION for another format version,
// resolution, margin or store; DATA_LOSS when truncated, altered or malformed.
Expected<std::unique_ptr<const ProxySet>> read_proxy_file(const std::string& path, const Manifest& manifest,
                                                          const ProxyBuildConfig& config);

// The header only, after checking magic, version, size and checksum (for
// `outcore info`); whether it matches a given store is for the caller.
Expected<ProxyFileHeader> read_proxy_file_header(const std::string& path);

}  // namespace outcore
