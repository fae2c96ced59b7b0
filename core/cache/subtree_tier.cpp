#include "core/cache/subtree_tier.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <system_error>
#include <utility>
#include <vector>

#include "core/util/atomic_file.h"
#include "core/util/checksum.h"

namespace outcore {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr std::string_view kPrefix = "brick-";
constexpr std::string_view kSuffix = ".subtree";
// Mappings per release batch at most (small bricks: the byte bound would
// queue thousands, each a range the kernel walks in one call).
constexpr std::size_t kMaxReleaseBatchMappings = 64;

std::string hex64(uint64_t value) {
  char text[17];
  std::snprintf(text, sizeof(text), "%016" PRIx64, value);
  return text;
}

bool is_subtree_file_name(const std::string& name) {
  return name.size() > kPrefix.size() + kSuffix.size() && name.starts_with(kPrefix) &&
         name.ends_with(kSuffix);
}

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace

SubtreeTier::SubtreeTier(const SubtreeTierOptions& options, const BrickSerializer& serializer)
    : options_(options),
      serializer_(serializer),
      structure_hash_(
          hex64(checksum64(serializer.structure_key().data(), serializer.structure_key().size()))),
      release_queue_(
          options.release_batch_bytes == 0
              ? nullptr
              : std::make_shared<PageReleaseQueue>(options.release_batch_bytes, kMaxReleaseBatchMappings)) {}

Expected<std::unique_ptr<SubtreeTier>> SubtreeTier::open(const SubtreeTierOptions& options,
                                                         const BrickSerializer& serializer) {
  if (options.directory.empty()) return invalid_argument("subtree tier: no directory given");
  std::error_code error;
  fs::create_directories(options.directory, error);
  if (error) return io_error("subtree tier: cannot create " + options.directory + ": " + error.message());
  if (!fs::is_directory(options.directory, error)) {
    return io_error("subtree tier: " + options.directory + " is not a directory");
  }
  std::unique_ptr<SubtreeTier> tier(new SubtreeTier(options, serializer));
  // Index what is there, least recently modified first.
  std::vector<std::pair<fs::file_time_type, std::pair<std::string, uint64_t>>> found;
  for (fs::directory_iterator it(options.directory, error), end; !error && it != end; it.increment(error)) {
    const std::string name = it->path().filename().string();
    std::error_code entry_error;
    if (!is_subtree_file_name(name) || !it->is_regular_file(entry_error)) continue;
    const uint64_t bytes = it->file_size(entry_error);
    const fs::file_time_type modified = it->last_write_time(entry_error);
    if (!entry_error) found.push_back({modified, {name, bytes}});
  }
  if (error) return io_error("subtree tier: cannot list " + options.directory + ": " + error.message());
  std::sort(found.begin(), found.end());
  std::lock_guard lock(tier->mutex_);
  for (const auto& [modified, file] : found) {
    tier->files_[file.first] = {file.second, ++tier->use_clock_, std::nullopt, nullptr, {}};
    ++tier->counters_.files;
    tier->counters_.bytes += file.second;
  }
  tier->evict_locked(0);
  return tier;
}

std::string SubtreeTier::file_name(const SubtreeKey& key) const {
  return std::string(kPrefix) + std::to_string(key.brick_id) + "-" + hex64(key.source_checksum) + "-" +
         structure_hash_ + std::string(kSuffix);
}

std::string SubtreeTier::path_of(const SubtreeKey& key) const {
  return (fs::path(options_.directory) / file_name(key)).string();
}

std::unique_ptr<BrickAccel> SubtreeTier::load(const SubtreeKey& key) {
  const std::string name = file_name(key);
  const std::string path = path_of(key);
  const auto start = Clock::now();
  std::optional<FileIdentity> trusted;
  // The kept copy, taken out of the index: while this load holds it, no
  // other load can read it or read into it.
  std::shared_ptr<MappedFile> kept;
  std::span<const char> kept_payload;
  {
    std::lock_guard lock(mutex_);
    const auto it = files_.find(name);
    if (it != files_.end()) {
      trusted = it->second.known_good;
      if (it->second.mapping != nullptr) {
        kept_payload = std::exchange(it->second.payload, {});
        kept = take_mapping_locked(it->second);
      }
    }
  }
  bool intact = false;  // kept, with its pages
  if (kept != nullptr) {
    // Still queued for release: its pages, hence its checked bytes, are
    // intact, and they are our own memory, so the file's state is moot.
    intact = release_queue_ != nullptr && release_queue_->cancel(kept.get());
    if (kept.use_count() != 1) {
      kept.reset();  // a brick or a release batch still reads it: not ours to reuse
      intact = false;
    } else if (intact) {
      std::unique_ptr<BrickAccel> accel =
          load_subtree_payload(kept, kept_payload, key, serializer_, release_queue_);
      if (accel != nullptr) {
        const double seconds = seconds_since(start);
        std::lock_guard lock(mutex_);
        ++counters_.loads;
        ++counters_.loads_kept;
        counters_.bytes_read += kept->bytes().size();
        counters_.load_seconds += seconds;
        const auto it = files_.find(name);
        if (it != files_.end()) it->second.last_use = ++use_clock_;
        keep_mapping_locked(name, kept, kept_payload);
        return accel;
      }
    }
  }
  // Its own copy's pages are gone (or it has none): another evicted brick's
  // queued copy, still populated, is cheaper to read into.
  // (An intact copy whose payload the serialiser refused, which it never
  // should, is read again as it is: given away, its pages would stay.)
  std::shared_ptr<MappedFile> recycled;
  if (!intact) {
    std::lock_guard lock(mutex_);
    recycled = take_queued_copy_locked(name, kept);
  }
  const bool recycling = recycled != nullptr;
  SubtreeReadResult read =
      read_subtree_file(path, key, serializer_, trusted, release_queue_,
                        recycling ? std::move(recycled) : std::move(kept), recycling || intact);
  const double seconds = seconds_since(start);

  std::lock_guard lock(mutex_);
  switch (read.rejection) {
    case SubtreeRejection::kNone: {
      ++counters_.loads;
      if (read.checked) ++counters_.loads_checked;
      if (read.reused) ++(recycling ? counters_.loads_recycled : counters_.loads_kept);
      counters_.bytes_read += read.file_bytes;
      counters_.load_seconds += seconds;
      const auto it = files_.find(name);
      if (it != files_.end()) {
        it->second.last_use = ++use_clock_;
        it->second.known_good = read.identity;
      }
      keep_mapping_locked(name, read.file, read.payload);
      return std::move(read.accel);
    }
    case SubtreeRejection::kAbsent:
      ++counters_.absent;
      forget_locked(name);
      return nullptr;
    case SubtreeRejection::kCorrupt: ++counters_.rejected_corrupt; break;
    case SubtreeRejection::kVersion: ++counters_.rejected_version; break;
    case SubtreeRejection::kStale: ++counters_.rejected_stale; break;
  }
  spdlog::warn("subtree tier: ignoring {} ({}); building brick {} instead", read.message,
               subtree_rejection_name(read.rejection), key.brick_id);
  std::error_code ignored;
  fs::remove(path, ignored);  // the rebuild writes a good one
  forget_locked(name);
  return nullptr;
}

std::unique_ptr<BrickAccel> SubtreeTier::store(const SubtreeKey& key, const BrickAccel& accel) {
  const std::string name = file_name(key);
  {
    std::lock_guard lock(mutex_);
    if (files_.count(name) != 0) return nullptr;
  }
  // A hidden temporary (no "brick-" prefix, so never indexed), renamed over
  // the brick's file once complete.
  AtomicFile file;
  file.prepare(path_of(key));
  const auto start = Clock::now();
  uint64_t bytes = 0;
  const Status written = write_subtree_file(file.temp_path(), key, serializer_, accel, &bytes);
  if (!written.ok()) {
    file.discard();
    std::lock_guard lock(mutex_);
    ++counters_.write_failures;
    if (!std::exchange(logged_write_failure_, true)) {
      spdlog::warn("subtree tier: cannot save brick {}: {} (further failures are only counted)", key.brick_id,
                   written.message());
    }
    return nullptr;
  }
  // Ours, under a name no one else uses: what we wrote, so known good.
  const Expected<FileIdentity> identity = file_identity(file.temp_path());
  const std::optional<FileIdentity> ours =
      identity.ok() ? std::optional<FileIdentity>(*identity) : std::nullopt;
  std::unique_lock lock(mutex_);
  if (options_.max_bytes > 0 && bytes > options_.max_bytes) {
    file.discard();
    ++counters_.writes_too_large;
    return nullptr;
  }
  evict_locked(bytes);
  if (const Status moved = file.commit(); !moved.ok()) {
    ++counters_.write_failures;
    if (!std::exchange(logged_write_failure_, true)) {
      spdlog::warn("subtree tier: cannot rename the file of brick {} into place: {}", key.brick_id,
                   moved.message());
    }
    return nullptr;
  }
  forget_locked(name);  // a file another process wrote meanwhile was replaced
  files_[name] = {bytes, ++use_clock_, ours, nullptr, {}};
  ++counters_.files;
  counters_.bytes += bytes;
  ++counters_.writes;
  counters_.bytes_written += bytes;
  counters_.write_seconds += seconds_since(start);
  lock.unlock();
  // The written file, mapped in place. Deleted meanwhile (a bound, another
  // process): nullptr, the caller keeps the built one; replaced by another
  // process since the rename (another identity): checked in full.
  SubtreeReadResult read = read_subtree_file(path_of(key), key, serializer_, ours, release_queue_);
  if (read.accel != nullptr) {
    lock.lock();
    keep_mapping_locked(name, read.file, read.payload);
  }
  return std::move(read.accel);
}

void SubtreeTier::keep_mapping_locked(const std::string& name, const std::shared_ptr<MappedFile>& file,
                                      std::span<const char> payload) {
  const auto it = files_.find(name);
  if (it == files_.end() || file == nullptr || it->second.mapping == file) return;
  if (it->second.mapping != nullptr) {
    owner_of_.erase(it->second.mapping.get());
  } else {
    if (kept_mappings_ >= kMaxKeptMappings) return;
    ++kept_mappings_;
  }
  it->second.mapping = file;
  it->second.payload = payload;
  owner_of_[file.get()] = &it->second;
}

std::shared_ptr<MappedFile> SubtreeTier::take_mapping_locked(FileEntry& entry) {
  if (entry.mapping == nullptr) return nullptr;
  owner_of_.erase(entry.mapping.get());
  --kept_mappings_;
  entry.payload = {};
  return std::move(entry.mapping);
}

std::shared_ptr<MappedFile> SubtreeTier::take_queued_copy_locked(const std::string& name,
                                                                 std::shared_ptr<MappedFile>& released) {
  if (release_queue_ == nullptr) return nullptr;
  const auto it = files_.find(name);
  if (it == files_.end()) return nullptr;
  std::shared_ptr<const MappedFile> queued =
      release_queue_->take(it->second.bytes, [&](const std::shared_ptr<const MappedFile>& copy) {
        // Held by the queue alone: its file was forgotten. Taken only when
        // the loader has no released copy, which would otherwise be unmapped
        // here, with nobody to give it to.
        if (copy.use_count() == 1) return released == nullptr;
        // Held by the queue and its brick's entry, nobody else: no accel
        // reads it, no load of that brick has taken it out (the entry would
        // no longer hold it), no release batch holds it. The brick gets the
        // loader's released copy in exchange, which must fit its file.
        const auto owner = owner_of_.find(copy.get());
        return copy.use_count() == 2 && owner != owner_of_.end() &&
               owner->second->mapping.get() == copy.get() &&
               (released == nullptr || released->capacity() >= copy->bytes().size());
      });
  if (queued == nullptr) return nullptr;
  // Made by this tier as a mutable MappedFile; the queue holds copies const.
  std::shared_ptr<MappedFile> copy = std::const_pointer_cast<MappedFile>(std::move(queued));
  if (const auto owner = owner_of_.find(copy.get()); owner != owner_of_.end()) {
    FileEntry& loser = *owner->second;
    (void)take_mapping_locked(loser);
    // Its next load reads its file into the exchanged copy (not queued, so
    // never taken for intact), or into a new one when it has none.
    if (released != nullptr) {
      loser.mapping = std::move(released);
      owner_of_[loser.mapping.get()] = &loser;
      ++kept_mappings_;
    }
  }
  return copy;
}

void SubtreeTier::evict_locked(uint64_t incoming) {
  if (options_.max_bytes == 0) return;
  while (!files_.empty() && counters_.bytes + incoming > options_.max_bytes) {
    const auto victim = std::min_element(files_.begin(), files_.end(), [](const auto& a, const auto& b) {
      return a.second.last_use < b.second.last_use;
    });
    std::error_code ignored;
    fs::remove(fs::path(options_.directory) / victim->first, ignored);
    ++counters_.files_evicted;
    forget_locked(victim->first);
  }
}

void SubtreeTier::forget_locked(const std::string& name) {
  const auto it = files_.find(name);
  if (it == files_.end()) return;
  --counters_.files;
  counters_.bytes -= it->second.bytes;
  (void)take_mapping_locked(it->second);
  files_.erase(it);
}

void SubtreeTier::release_pending_pages() {
  if (release_queue_ != nullptr) release_queue_->flush();
}

PageReleaseCounters SubtreeTier::page_release_counters() const {
  return release_queue_ != nullptr ? release_queue_->counters() : PageReleaseCounters{};
}

SubtreeTierCounters SubtreeTier::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace outcore
