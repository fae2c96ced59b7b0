// Subtree files: one built brick structure saved by the subtree tier
// (subtree_tier.h), so a later miss can load it instead of building it again.
//
// Layout (version 2; all integers little-endian, as cereal's binary archive
// writes them on the little-endian hosts the store already requires):
//
//   magic            8 bytes "OCSUBTR\x1a"
//   format_version   uint32 (kSubtreeFormatVersion)
//   brick_id         uint32   -.
//   source_checksum  uint64    | cereal binary archive of SubtreeKey: the
//   triangle_count   uint32    | store brick it was built from (the
//   structure_key    string   -'  manifest's XXH3-64 of the brick) and how
//   zero bytes       to the next multiple of 64 (kSubtreePayloadAlignment)
//   payload          the BrickSerializer's bytes (to the trailer)
//   checksum         uint64 XXH3-64 of every byte before it
//
// The payload starts 64-byte aligned in the file, hence in a mapping of it,
// so a serialiser can use its arrays in place (the bvh brick does).
//
// A file is used only when magic, version and checksum are right and its key
// equals the one asked for: the same brick id, the same source bytes (so a
// file from another store, or from before a repack, is never used unless the
// brick is bitwise the same, when the structure is too) and the same
// structure key (structure, payload version and every option). Anything else
// is a rejection with a reason; the caller rebuilds.
//
// A file is read into memory of its own (MappedFile::copy) and its checksum
// verified on that copy at every read, so a file truncated or overwritten
// later, even while its brick is traversed, never reaches a ray. A caller
// that knows the file is one it wrote or fully checked before, unchanged
// since (same FileIdentity), may skip the serialiser's structural checks
// (known_good): the checksum then proves the bytes are those checked.
//
// Thread-safety: functions of their arguments; concurrent calls on different
// paths are independent.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "core/accel/brick_serializer.h"
#include "core/util/mapped_file.h"
#include "core/util/page_release_queue.h"
#include "core/util/status.h"

namespace outcore {

inline constexpr char kSubtreeMagic[8] = {'O', 'C', 'S', 'U', 'B', 'T', 'R', '\x1a'};
inline constexpr uint32_t kSubtreeFormatVersion = 2;
inline constexpr std::size_t kSubtreePayloadAlignment = 64;

struct SubtreeKey {
  uint32_t brick_id = 0;
  uint64_t source_checksum = 0;  // BrickRecord::checksum
  uint32_t triangle_count = 0;
  std::string structure_key;  // BrickSerializer::structure_key()

  bool operator==(const SubtreeKey&) const = default;

  template <class Archive>
  void serialize(Archive& ar) {
    ar(brick_id, source_checksum, triangle_count, structure_key);
  }
};

// Why a file was not used.
enum class SubtreeRejection : uint8_t {
  kNone,     // it was used
  kAbsent,   // no such file
  kCorrupt,  // wrong magic, truncated, checksum mismatch, or a payload the serialiser refuses
  kVersion,  // another format version
  kStale,    // a valid file for another key (brick bytes, structure or options)
};
const char* subtree_rejection_name(SubtreeRejection rejection);

struct SubtreeReadResult {
  std::unique_ptr<BrickAccel> accel;  // set when rejection == kNone
  // When loaded: the file's copy and the payload's bytes in it, for
  // load_subtree_payload() to load the brick again.
  std::shared_ptr<MappedFile> file;
  std::span<const char> payload;
  SubtreeRejection rejection = SubtreeRejection::kAbsent;
  std::string message;  // why, naming the file, when rejected (not when absent)
  uint64_t file_bytes = 0;
  FileIdentity identity;  // of the file read, when there was one
  bool checked = false;   // the checksum and structural checks ran (it was not trusted)
  bool reused = false;    // read into the `reuse` copy (no new mapping)
};

// Writes `accel` under `key` to a new file at `path` (which must not exist);
// the caller renames it into place. Sets *file_bytes to the file's size.
Status write_subtree_file(const std::string& path, const SubtreeKey& key, const BrickSerializer& serializer,
                          const BrickAccel& accel, uint64_t* file_bytes);

// Reads `path` if it holds `key`; never throws. The loaded accel keeps the
// file's copy and reads it in place. `trusted`: the identity of a file the
// caller wrote or checked in full before; when the file at `path` still has
// it, it is known good (see above): the checksum is verified, the structure
// is not. `release_queue`: where the accel, once dropped while someone else
// still holds the copy, queues its pages for release (nullptr: released at
// once). `reuse`: a copy that nobody else holds (use_count 1), of an
// earlier read of this path or of another file, read into in place
// (MappedFile::read_again, `reuse_pages_kept` passed on) when the file fits
// its capacity, so the load maps no memory; otherwise a new copy is made.
SubtreeReadResult read_subtree_file(const std::string& path, const SubtreeKey& key,
                                    const BrickSerializer& serializer,
                                    const std::optional<FileIdentity>& trusted = std::nullopt,
                                    std::shared_ptr<PageReleaseQueue> release_queue = nullptr,
                                    std::shared_ptr<MappedFile> reuse = nullptr,
                                    bool reuse_pages_kept = false);

// Loads again, in place and without checks, a payload read_subtree_file()
// loaded into `file` before, whose pages were not released since (the copy
// is this process's own memory: nothing outside can change it). nullptr when
// the serialiser refuses it (it never should).
std::unique_ptr<BrickAccel> load_subtree_payload(const std::shared_ptr<const MappedFile>& file,
                                                 std::span<const char> payload, const SubtreeKey& key,
                                                 const BrickSerializer& serializer,
                                                 std::shared_ptr<PageReleaseQueue> release_queue = nullptr);

}  // namespace outcore
