#include "core/cache/subtree_file.h"

#include <cereal/archives/binary.hpp>
#include <cereal/types/string.hpp>

#include <cstring>
#include <istream>
#include <memory>
#include <new>
#include <ostream>

#include "core/util/checksum.h"
#include "core/util/checksumming_file_streambuf.h"
#include "core/util/mapped_file.h"
#include "core/util/span_streambuf.h"

namespace outcore {
namespace {

// The accel's hold on a subtree file's copy. When someone else keeps the
// copy too (the tier, to read the brick into it again without mapping new
// memory), dropping the lease releases the pages the accel read (through the
// tier's PageReleaseQueue when it has one, else MappedFile::release_pages at
// once), so an evicted brick holds no RSS; otherwise dropping the last
// holder unmaps the copy.
struct SubtreeMappingLease {
  SubtreeMappingLease(std::shared_ptr<const MappedFile> mapped, std::shared_ptr<PageReleaseQueue> queue)
      : file(std::move(mapped)), release_queue(std::move(queue)) {}
  ~SubtreeMappingLease() {
    if (file.use_count() <= 1) return;
    if (release_queue != nullptr) {
      release_queue->release(std::move(file));
    } else {
      file->release_pages();
    }
  }
  SubtreeMappingLease(const SubtreeMappingLease&) = delete;
  SubtreeMappingLease& operator=(const SubtreeMappingLease&) = delete;

  std::shared_ptr<const MappedFile> file;
  std::shared_ptr<PageReleaseQueue> release_queue;
};

constexpr std::size_t kPreambleBytes = sizeof(kSubtreeMagic) + sizeof(uint32_t);
constexpr std::size_t kTrailerBytes = sizeof(uint64_t);

uint64_t aligned(uint64_t offset) {
  return (offset + kSubtreePayloadAlignment - 1) / kSubtreePayloadAlignment * kSubtreePayloadAlignment;
}

SubtreeReadResult rejected(SubtreeRejection why, const std::string& path, const std::string& message) {
  SubtreeReadResult result;
  result.rejection = why;
  result.message = path + ": " + message;
  return result;
}

std::string describe(const SubtreeKey& key) {
  return "brick " + std::to_string(key.brick_id) + ", source checksum " +
         std::to_string(key.source_checksum) + ", " + std::to_string(key.triangle_count) + " triangles, '" +
         key.structure_key + "'";
}

// The serialiser's load of `payload`, in place, the accel holding `file`
// through a lease; never throws.
Expected<std::unique_ptr<BrickAccel>> load_leased(std::shared_ptr<const MappedFile> file,
                                                  std::shared_ptr<PageReleaseQueue> release_queue,
                                                  std::span<const char> payload, const SubtreeKey& key,
                                                  const BrickSerializer& serializer, bool known_good) {
  try {
    const SerializedBrick serialized{
        payload, std::make_shared<const SubtreeMappingLease>(std::move(file), std::move(release_queue)),
        known_good};
    return serializer.load(serialized, key.brick_id, key.triangle_count);
  } catch (const std::bad_alloc&) {
    return resource_exhausted("out of memory while loading");
  }
}

}  // namespace

const char* subtree_rejection_name(SubtreeRejection rejection) {
  switch (rejection) {
    case SubtreeRejection::kNone: return "none";
    case SubtreeRejection::kAbsent: return "absent";
    case SubtreeRejection::kCorrupt: return "corrupt";
    case SubtreeRejection::kVersion: return "version";
    case SubtreeRejection::kStale: return "stale";
  }
  return "?";
}

Status write_subtree_file(const std::string& path, const SubtreeKey& key, const BrickSerializer& serializer,
                          const BrickAccel& accel, uint64_t* file_bytes) {
  ChecksummingFileStreambuf file;
  OUTCORE_RETURN_IF_ERROR(file.create(path));
  std::ostream out(&file);
  out.write(kSubtreeMagic, sizeof(kSubtreeMagic));
  const uint32_t version = kSubtreeFormatVersion;
  out.write(reinterpret_cast<const char*>(&version), sizeof(version));
  try {
    cereal::BinaryOutputArchive archive(out);
    archive(key);
  } catch (const std::exception& e) {
    return io_error("writing " + path + ": " + e.what());
  }
  static constexpr char kZeros[kSubtreePayloadAlignment] = {};
  const uint64_t written = file.size();
  out.write(kZeros, static_cast<std::streamsize>(aligned(written) - written));
  Status saved = serializer.save(accel, out);
  if (saved.ok() && !out) saved = io_error("writing " + path + " failed");
  if (!saved.ok()) {
    (void)file.close();
    return saved.with_context("writing " + path);
  }
  const uint64_t checksum = file.checksum();
  OUTCORE_RETURN_IF_ERROR(file.append_unchecked(&checksum, sizeof(checksum)));
  if (file_bytes != nullptr) *file_bytes = file.size();
  return file.close();
}

SubtreeReadResult read_subtree_file(const std::string& path, const SubtreeKey& key,
                                    const BrickSerializer& serializer,
                                    const std::optional<FileIdentity>& trusted,
                                    std::shared_ptr<PageReleaseQueue> release_queue,
                                    std::shared_ptr<MappedFile> reuse, bool reuse_pages_kept) {
  std::shared_ptr<MappedFile> file;
  bool reused = false;
  if (reuse != nullptr) {
    Status again = reuse->read_again(path, reuse_pages_kept);
    if (again.ok()) {
      file = std::move(reuse);
      reused = true;
    } else if (again.code() != StatusCode::kFailedPrecondition) {  // too large: a new copy below
      if (again.code() == StatusCode::kNotFound) return SubtreeReadResult{};
      return rejected(SubtreeRejection::kCorrupt, path, again.message());
    }
  }
  if (file == nullptr) {
    Expected<MappedFile> copied = MappedFile::copy(path);
    if (!copied.ok()) {
      if (copied.status().code() == StatusCode::kNotFound) return SubtreeReadResult{};
      return rejected(SubtreeRejection::kCorrupt, path, copied.status().message());
    }
    file = std::make_shared<MappedFile>(std::move(copied).value());
  }
  const FileIdentity identity = file->identity();
  const bool known_good = trusted.has_value() && *trusted == identity;
  const std::span<const char> bytes = file->bytes();
  if (bytes.size() < kPreambleBytes + kTrailerBytes) {
    return rejected(SubtreeRejection::kCorrupt, path,
                    "truncated (" + std::to_string(bytes.size()) + " bytes, no header)");
  }
  if (std::memcmp(bytes.data(), kSubtreeMagic, sizeof(kSubtreeMagic)) != 0) {
    return rejected(SubtreeRejection::kCorrupt, path, "not a subtree file (wrong magic)");
  }
  uint32_t version = 0;
  std::memcpy(&version, bytes.data() + sizeof(kSubtreeMagic), sizeof(version));
  if (version != kSubtreeFormatVersion) {
    return rejected(SubtreeRejection::kVersion, path,
                    "format version " + std::to_string(version) + ", this build reads version " +
                        std::to_string(kSubtreeFormatVersion));
  }
  // Always, known good or not: a file of the same identity may still have
  // been written in place (mtime restored, or within its granularity), and
  // these bytes are what rays will read.
  const std::size_t checked = bytes.size() - kTrailerBytes;
  uint64_t stored = 0;
  std::memcpy(&stored, bytes.data() + checked, sizeof(stored));
  if (checksum64(bytes.data(), checked) != stored) {
    return rejected(SubtreeRejection::kCorrupt, path, "checksum mismatch (truncated or altered)");
  }
  const std::span<const char> body = bytes.subspan(kPreambleBytes, checked - kPreambleBytes);
  SubtreeKey found;
  SpanStreambuf buffer(body);
  try {
    std::istream in(&buffer);
    cereal::BinaryInputArchive archive(in);
    archive(found);
  } catch (const std::exception& e) {
    return rejected(SubtreeRejection::kCorrupt, path, std::string("unreadable header: ") + e.what());
  }
  if (!(found == key)) {
    return rejected(SubtreeRejection::kStale, path, "holds " + describe(found) + "; wanted " + describe(key));
  }
  const std::size_t payload_offset = aligned(checked - buffer.remaining());
  if (payload_offset > checked) {
    return rejected(SubtreeRejection::kCorrupt, path, "truncated (no payload after the header)");
  }
  SubtreeReadResult result;
  result.file_bytes = bytes.size();
  result.identity = identity;
  result.checked = !known_good;
  result.reused = reused;
  result.payload = bytes.subspan(payload_offset, checked - payload_offset);
  result.file = file;
  Expected<std::unique_ptr<BrickAccel>> loaded =
      load_leased(std::move(file), std::move(release_queue), result.payload, key, serializer, known_good);
  if (!loaded.ok()) return rejected(SubtreeRejection::kCorrupt, path, loaded.status().message());
  result.accel = std::move(loaded).value();
  result.rejection = SubtreeRejection::kNone;
  return result;
}

std::unique_ptr<BrickAccel> load_subtree_payload(const std::shared_ptr<const MappedFile>& file,
                                                 std::span<const char> payload, const SubtreeKey& key,
                                                 const BrickSerializer& serializer,
                                                 std::shared_ptr<PageReleaseQueue> release_queue) {
  Expected<std::unique_ptr<BrickAccel>> loaded =
      load_leased(file, std::move(release_queue), payload, key, serializer, true);
  return loaded.ok() ? std::move(loaded).value() : nullptr;
}

}  // namespace outcore
