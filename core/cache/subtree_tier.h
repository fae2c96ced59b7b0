// SubtreeTier: a directory of built brick structures (subtree files,
// subtree_file.h) between the brick cache and the scene store. When the cache
// builds a brick it saves the result here; on a later miss (after an
// eviction, or in a later process) it loads the file instead of building
// again. Only for brick structures with a BrickSerializer ("bvh").
//
// - Written on build, not on eviction: the building thread is off the
//   cache's lock, the file is there for the next process too, and evicting
//   (which happens while another thread waits for room) stays as cheap as
//   before. store() then hands back the written file loaded (a copy, below),
//   which the cache keeps instead of the heap build: every resident brick is
//   then a mapping of its own that eviction releases, so the allocator never
//   holds freed brick memory next to them (process RSS stays within the
//   budget plus a fixed overhead). Each brick is written once per directory (a brick
//   the tier knows is on disk is not written again).
// - Atomic: a file is written under a temporary name in the directory and
//   renamed into place (AtomicFile, core/util/atomic_file.h), so readers (of
//   this or another process) see a whole file or none. Not fsync'ed: after a crash a file may be torn, which
//   its checksum catches. A writer that crashes mid-file leaves its hidden temporary (".brick-*.tmp-PID-N"),
//   which is never read; delete it by hand.
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
// - Loads copy: a file is read into memory of this process's own (a private
//   anonymous mapping, MappedFile::copy) and its checksum verified on that
//   copy at every read; the loaded accel reads the copy in place. The
//   directory is outside this process's control (another process or user may
//   truncate or overwrite a file in place while its brick is traversed): a
//   damaged file costs a rebuild, never the process nor a wrong answer. The
//   structural checks run the first time this tier loads a file; later loads
//   of the same, unchanged file (same FileIdentity: inode, size, modification
//   time), and loads of files this tier wrote, skip them (the checksum proves
//   the bytes are those checked). A file replaced by another process (a new
//   inode) is checked again. The cost against reading the file in place
//   (mapped): a copy and a checksum a load (docs/CACHE_TUNING.md).
// - Copies are kept (up to kMaxKeptMappings): a loaded or written file's
//   copy stays mapped after the cache evicts its brick, with its pages
//   released (MappedFile::release_pages: they leave the RSS), and the next
//   load of that brick reads the file again into that memory (or into a
//   recycled copy, below): no mmap or munmap, which take the process's
//   mapping lock for writing and stall every other thread's page faults (a
//   warm batch at a quarter budget loads thousands of bricks). Released
//   pages are batched (PageReleaseQueue, release_batch_bytes of copies at
//   most, flushed at the end of each query batch), and a queued copy loaded
//   again is taken out of the queue with its pages: its bytes, checked and
//   our own, are used without reading the file. A kept copy is dropped when
//   this tier deletes the file or forgets it.
// - Queued copies are recycled: a load whose own copy's pages were released
//   (or that has none) takes another evicted brick's copy still waiting in
//   the release queue, pages populated, and reads its file into those pages
//   (MappedFile::read_again), instead of populating released pages again
//   (most of such a load's cost). That brick gets the loader's released copy
//   in exchange, into which its own next load reads (or none, when the
//   loader had none: its next load then recycles in turn or makes a new
//   copy, so copies are made at most once per brick). Only a copy nobody
//   else holds is taken (its brick's entry and the queue: no accel reads
//   it), of a capacity that fits the file and with no more pages populated
//   than the file fills, so the RSS holds only what the cache accounts for
//   the loaded brick, as for any load; the queue holds less meanwhile. The
//   checksum is verified as for any read.
//
// Thread-safety: all member functions may be called from any thread; one
// mutex guards the index and is held for renames and deletions, never while
// reading, checking or writing a file; the release queue's lock is taken
// under it (to take a queued copy), never the other way round.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>

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
  uint64_t loads_checked = 0;   // of the loads, those that checked the file in full
  uint64_t loads_kept = 0;      // of the loads, those that reused their brick's kept copy
  uint64_t loads_recycled = 0;  // those that read into another evicted brick's queued copy
  double load_seconds = 0;      // map + check + deserialise, summed over loads
  double write_seconds = 0;     // serialise + write + rename, summed over writes
  uint64_t files = 0;           // in the directory now, as far as this tier knows
  uint64_t bytes = 0;           // their size

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
    std::shared_ptr<MappedFile> mapping;
    std::span<const char> payload;
  };

  SubtreeTier(const SubtreeTierOptions& options, const BrickSerializer& serializer);
  std::string file_name(const SubtreeKey& key) const;
  // Under the lock: deletes least recently used files until `incoming` more
  // bytes fit in the bound.
  void evict_locked(uint64_t incoming);
  void forget_locked(const std::string& name);
  // Under the lock: keeps `file` (a loaded copy, `payload` in it) in the
  // entry for `name`, if known and below the limit.
  void keep_mapping_locked(const std::string& name, const std::shared_ptr<MappedFile>& file,
                           std::span<const char> payload);
  // Under the lock: the entry's kept copy, taken out of it (nullptr: none).
  std::shared_ptr<MappedFile> take_mapping_locked(FileEntry& entry);
  // Under the lock: another brick's copy, taken out of the release queue
  // (pages populated) to read the file `name` into, or nullptr (see above).
  // `released`, the loader's own copy (pages released) or nullptr, goes to
  // the entry that loses the copy, if any.
  std::shared_ptr<MappedFile> take_queued_copy_locked(const std::string& name,
                                                      std::shared_ptr<MappedFile>& released);

  const SubtreeTierOptions options_;
  const BrickSerializer& serializer_;
  const std::string structure_hash_;  // of the structure key, for file names
  // Where loaded bricks queue their pages when evicted (null: released at once).
  const std::shared_ptr<PageReleaseQueue> release_queue_;

  mutable std::mutex mutex_;
  std::map<std::string, FileEntry> files_;  // by file name
  // The entry keeping each kept copy (map nodes do not move).
  std::unordered_map<const MappedFile*, FileEntry*> owner_of_;
  uint64_t use_clock_ = 0;
  uint64_t kept_mappings_ = 0;
  bool logged_write_failure_ = false;
  SubtreeTierCounters counters_;
};

}  // namespace outcore
