// The on-disk layout of a scene store, in one place. A store is a directory:
//   manifest.bin  header (StoreFileHeader) + cereal portable-binary Manifest
//   bricks.dat    bricks one after another, each at a 4 KiB-aligned offset:
//                 BrickHeader, then positions (float32 x 9 per triangle:
//                 v0 v1 v2), then ids (uint32 x 2 per triangle: geometry_id,
//                 primitive_id). All little-endian.
// The manifest records every brick's offset, size and XXH3-64 checksum of its
// bytes (header included). Readers refuse other format versions by number.
//
// Thread-safety: constants and plain structs.
#pragma once

#include <cstdint>

namespace outcore {

// 2: bricks carry a bounding sphere and an oriented box (issue 24).
inline constexpr uint32_t kStoreFormatVersion = 2;
inline constexpr char kManifestFileName[] = "manifest.bin";
inline constexpr char kBrickDataFileName[] = "bricks.dat";
// The bricks' occupancy proxies (core/proxy/proxy_file.h), cached beside them.
inline constexpr char kProxyFileName[] = "proxies.bin";
inline constexpr uint64_t kBrickAlignment = 4096;

// 8-byte magics; the last byte guards against text-mode mangling.
inline constexpr char kManifestMagic[8] = {'O', 'U', 'T', 'C', 'O', 'R', 'E', '\x1a'};
inline constexpr char kBrickMagic[8] = {'O', 'C', 'B', 'R', 'I', 'C', 'K', '\x1a'};

struct StoreFileHeader {
  char magic[8];
  uint32_t format_version;
  uint32_t header_bytes;  // sizeof(StoreFileHeader), for future growth
  uint64_t payload_bytes;
  uint64_t payload_checksum;  // XXH3-64 of the payload
};
static_assert(sizeof(StoreFileHeader) == 32);

struct BrickHeader {
  char magic[8];
  uint32_t brick_id;
  uint32_t triangle_count;
  uint64_t payload_bytes;  // bytes after this header
  uint64_t reserved;
};
static_assert(sizeof(BrickHeader) == 32);

inline constexpr uint64_t brick_payload_bytes(uint64_t triangles) {
  return triangles * (36 + 8);
}
inline constexpr uint64_t brick_total_bytes(uint64_t triangles) {
  return sizeof(BrickHeader) + brick_payload_bytes(triangles);
}

}  // namespace outcore
