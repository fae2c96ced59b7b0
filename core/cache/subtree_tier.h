// SubtreeTier: a directory of built brick structures (subtree files,
// subtree_file.h) between the brick cache and the scene store. When the cache
// builds a brick it saves the result here; on a later miss (after an
// eviction, or in a later process) it loads the file instead of building
// again. Only for brick structures with a BrickSerializer ("bvh").
//
// - Written on build, not on eviction: the building thread is off the
//   cache's lock, the file is there for the next process too, and evicting
//   (which happens while another thread waits for room) stays as cheap as
//   before. store() then hands back the written file mapped in place, which
//   the cache keeps instead of the built copy: every resident brick is then
//   page-cache pages that eviction unmaps, so the allocator never holds freed
//   brick memory next to mapped bricks (process RSS stays within the budget
//   plus a fixed overhead). Each brick is written once per directory (a brick
//   the tier knows is on disk is not written again).
// - Atomic: a file is written under a temporary name in the directory and
//   renamed into place, so readers (of this or another process) see a whole
//   file or none. Not fsync'ed: after a crash a file may be torn, which its
//   checksum catches. A writer that crashes mid-file leaves its hidden
//   temporary (".brick-*.tmp-PID-N"), which is never read; delete it by hand.
// - Keyed by brick id, the source brick's checksum and the structure key, all
//   in the file name and checked again in the header: several stores and
//   configurations may share one directory.
// - Bounded (max_bytes > 0): the files this tier knows (found at open, plus
//   those it writes) are kept within max_bytes by deleting the least recently
//   used (loaded or written; at open, oldest modification first). A file
//   larger than the whole bound is not written. 0 means unbounded. Processes
//   sharing a directory each keep their own view (files another process
//   writes later are used but not counted).
// - A file that is corrupt, truncated, of another version or stale (another
//   key under the expected name) is counted by reason, logged, deleted, and
//   the caller builds instead: never a wrong answer.
// - Loads are in place: the loaded accel reads the mapped file (the page
//   cache's pages, faulted in as traversal touches them) and unmaps it when
//   the cache evicts it, so the cache's budget still bounds what the process
//   holds. A file is checked in full (checksum, structure) the first time this tier loads it;
//   later loads of the same, unchanged file (same FileIdentity: inode, size,
//   modification time), and loads of files this tier wrote, skip those checks
//   and cost a mapping and a header check. A file replaced by another
//   process (a new inode) is checked again.
// - Mappings are kept (up to kMaxKeptMappings): a loaded or written file
//   stays mapped after the cache evicts its brick, with its pages released
//   (MappedFile::release_pages: they leave the RSS, the page cache keeps
//   them), and the next load of that brick reuses the mapping while the path
//   still names that file unchanged (one stat): no open, no mmap, no header
//   check. Released pages are batched (PageReleaseQueue, release_batch_bytes
//   of mappings at most, flushed at the end of each query batch), and a
//   queued mapping loaded again is taken out of the queue with its pages.
//   Mapping and unmapping take the process's mapping
//   lock for writing, which stalls every other thread's page faults; a warm
//   batch at a quarter budget loads thousands of bricks. A kept mapping is
//   dropped when this tier deletes the file or forgets it, and not used when
//   the file was replaced, edited or deleted since (it is then read again).
//
// Thread-safety: all member functions may be called from any thread; one
// mutex guards the index and is held for renames and deletions, never while
// reading, checking or writing a file.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/accel/brick_serializer.h"
#include "core/cache/subtree_file.h"
#include "core/util/mapped_file.h"
#include "core/util/status.h"

namespace outcore {

// Evicted bricks' pages are released in batches of this many bytes of
// mappings (PageReleaseQueue): one system call, and one TLB flush on recent
// kernels, per batch instead of per brick. They stay in the RSS until then.
inline constexpr uint64_t kDefaultReleaseBatchBytes = uint64_t{32} << 20;

struct SubtreeTierOptions {
  std::string directory;   // created if missing
  uint64_t max_bytes = 0;  // 0: unbounded
  // 0: each evicted brick's pages are released at once.
  uint64_t release_batch_bytes = kDefaultReleaseBatchBytes;
};

struct SubtreeTierCounters {
  uint64_t loads = 0;   // lookups served by a valid file
  uint64_t absent = 0;  // lookups that found no file
  uint64_t rejected_corrupt = 0;
  uint64_t rejected_version = 0;
  uint64_t rejected_stale = 0;
  uint64_t writes = 0;
  uint64_t write_failures = 0;    // I/O errors (the first one is logged)
  uint64_t writes_too_large = 0;  // files larger than the whole bound, not kept
  uint64_t files_evicted = 0;
  uint64_t bytes_read = 0;  // of the files loaded
  uint64_t bytes_written = 0;
  uint64_t loads_checked = 0;  // of the loads, those that checked the file in full
  uint64_t loads_kept = 0;     // of the loads, those that reused a kept mapping
  double load_seconds = 0;     // map + check + deserialise, summed over loads
  double write_seconds = 0;    // serialise + write + rename, summed over writes
  uint64_t files = 0;          // in the directory now, as far as this tier knows
  uint64_t bytes = 0;          // their size

  uint64_t rejected() const { return rejected_corrupt + rejected_version + rejected_stale; }
};

// Kept mappings at most (each is one of the process's memory mappings, which
// Linux limits to vm.max_map_count, 65,530 by default).
inline constexpr uint64_t kMaxKeptMappings = 16384;

class SubtreeTier {
 public:
  // Creates the directory if needed and indexes the subtree files in it.
  // IO_ERROR when it cannot be created or listed.
  static Expected<std::unique_ptr<SubtreeTier>> open(const SubtreeTierOptions& options,
                                                     const BrickSerializer& serializer);
  SubtreeTier(const SubtreeTier&) = delete;
  SubtreeTier& operator=(const SubtreeTier&) = delete;

  // The structure saved under `key`, or nullptr when there is no valid one.
  std::unique_ptr<BrickAccel> load(const SubtreeKey& key);
  // Saves `accel` under `key` unless a file for it is known to exist, and
  // returns the saved file loaded in place (the same answers and
  // memory_bytes() as `accel`), or nullptr when nothing was saved; the caller
  // then keeps `accel`. Failures are counted and logged, never returned: the
  // tier is a cache.
  std::unique_ptr<BrickAccel> store(const SubtreeKey& key, const BrickAccel& accel);

  // Releases the pages of evicted bricks still queued for release (the end
  // of a batch: nothing held beyond the budget between batches).
  void release_pending_pages();
  PageReleaseCounters page_release_counters() const;

  // Where the file for `key` lives (tests, tools).
  std::string path_of(const SubtreeKey& key) const;
  SubtreeTierCounters counters() const;
  const SubtreeTierOptions& options() const { return options_; }
  const BrickSerializer& serializer() const { return serializer_; }

 private:
  struct FileEntry {
    uint64_t bytes = 0;
    uint64_t last_use = 0;
    // The file as this tier wrote or last checked it in full.
    std::optional<FileIdentity> known_good;
    // That file kept mapped, and its payload, to load it again (see above).
    std::shared_ptr<const MappedFile> mapping;
    std::span<const char> payload;
  };

  SubtreeTier(const SubtreeTierOptions& options, const BrickSerializer& serializer);
  std::string file_name(const SubtreeKey& key) const;
  // Under the lock: deletes least recently used files until `incoming` more
  // bytes fit in the bound.
  void evict_locked(uint64_t incoming);
  void forget_locked(const std::string& name);
  // Under the lock: keeps `read`'s mapping in the entry for `name`, if known
  // and below the limit.
  void keep_mapping_locked(const std::string& name, const SubtreeReadResult& read);

  const SubtreeTierOptions options_;
  const BrickSerializer& serializer_;
  const std::string structure_hash_;  // of the structure key, for file names
  // Where loaded bricks queue their pages when evicted (null: released at once).
  const std::shared_ptr<PageReleaseQueue> release_queue_;

  mutable std::mutex mutex_;
  std::map<std::string, FileEntry> files_;  // by file name
  uint64_t use_clock_ = 0;
  uint64_t kept_mappings_ = 0;
  uint64_t temp_sequence_ = 0;
  bool logged_write_failure_ = false;
  SubtreeTierCounters counters_;
};

}  // namespace outcore
