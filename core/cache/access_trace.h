// Brick access traces: one record per successful brick acquisition of a
// BrickCache, in the order the cache served them, for offline replay
// (cache_simulator.h, `outcore cache-sim`).
//
// File format (CSV, version 3), chosen to be read by people and by pandas:
//
//   # outcore brick access trace, version 3
//   # policy: lru
//   # budget_bytes: 67108864
//   # builder: embree
//   # bricks: 640
//   # source: trace scene.oc rays.npy
//   seq,brick,bytes,reserved_bytes,build_seconds,outcome,structure,rays
//   0,17,1433600,2097152,0.00231,miss,grid,40
//   1,17,1433600,2097152,0,hit,grid,512
//
// The first line names the version; other "# key: value" lines are metadata
// (all optional); the column line is required. seq counts records from 0 in
// file order. bytes: the brick's accounted bytes (after the build on a miss,
// the resident size on a hit). reserved_bytes: the builder's upper bound the
// cache reserves before building it (BrickBuilder::reserve_bytes).
// build_seconds: measured load + build time on a miss (with a subtree tier,
// plus writing the subtree file; on a load, the file's load time), 0
// otherwise, written with 17 significant digits so a replay feeds GDSF the
// very same cost. outcome: miss (this request built the
// brick), load (this request loaded it from the subtree tier instead of
// building it; subtree_tier.h), hit (it was ready), wait (it was being built
// by another thread and this request waited for that build). Version 2 added
// "load"; version 3 added structure (the brick's structure: the builder's,
// or with --brick-accel auto the one it chose) and rays (how many rays the
// acquisition was for, what auto chooses by; 0 when the engine does not
// know, e.g. bricks pinned for a whole in-cache sweep). Versions 1 and 2
// (without these columns) are read too.
// Failed acquisitions are not recorded. A line "# hint: 12 7 40" (brick ids,
// soonest first; possibly none) before a record is the schedule hint the
// engine gave the policy before that request (schedule-aware policies use
// it); being a comment line, CSV readers skip it.
//
// The reader bounds byte counts so that replays never overflow: every
// record's bytes and reserved_bytes, summed over the whole trace, stay within
// kMaxTraceBytes (2^62; a real trace is many orders of magnitude below it).
// Any sum a replay forms (working set, resident bytes plus a reservation,
// bytes built) is then exact in 64 bits.
//
// Thread-safety: AccessTraceWriter::append/close may be called from any thread
// (one mutex, never taken under the cache's lock); the reader is a function.
#pragma once

#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace outcore {

enum class AccessOutcome : uint8_t { kHit, kMiss, kWait, kLoad };
const char* access_outcome_name(AccessOutcome outcome);

struct AccessRecord {
  uint64_t seq = 0;
  uint32_t brick = 0;
  uint64_t bytes = 0;
  uint64_t reserved_bytes = 0;
  double build_seconds = 0;
  AccessOutcome outcome = AccessOutcome::kHit;
  // The brick's structure (a brick_accel_names() name; with auto, the chosen
  // one; empty in traces before version 3) and the rays the acquisition was
  // for (BrickCache::acquire; 0 when not known or before version 3).
  std::string structure;
  uint64_t rays = 0;
  // The schedule hint the cache's policy was given just before this request
  // (EvictionPolicy::on_schedule_hint), when there was one since the last
  // request; a replay hands it to the policy at the same point.
  bool has_hint = false;
  std::vector<uint32_t> hint;
};

// The metadata lines; empty or zero when a trace does not give them.
struct AccessTraceInfo {
  std::string policy;
  uint64_t budget_bytes = 0;
  std::string builder;
  uint32_t bricks = 0;
  std::string source;
};

struct AccessTrace {
  AccessTraceInfo info;
  std::vector<AccessRecord> records;
};

inline constexpr int kAccessTraceVersion = 3;
// The most bytes a trace's records may count in all (see above), and the
// largest cache budget a replay accepts.
inline constexpr uint64_t kMaxTraceBytes = uint64_t{1} << 62;
inline constexpr int kOldestAccessTraceVersion = 1;  // still read

class AccessTraceWriter {
 public:
  // Creates (or truncates) `path`; `source` goes into the metadata.
  static Expected<std::shared_ptr<AccessTraceWriter>> create(const std::string& path, std::string source);
  ~AccessTraceWriter();
  AccessTraceWriter(const AccessTraceWriter&) = delete;
  AccessTraceWriter& operator=(const AccessTraceWriter&) = delete;

  // Metadata from the cache that records into this writer; must come before
  // the first append (BrickCache::set_access_trace calls it).
  void set_info(const std::string& policy, uint64_t budget_bytes, const std::string& builder,
                uint32_t bricks);
  // A chunk of consecutive records (by seq). Chunks may arrive out of order
  // from different threads; they are written in seq order.
  void append(std::vector<AccessRecord> chunk);
  // Writes what is pending and closes the file; the first write error, if
  // any. Later appends are dropped.
  Status close();
  uint64_t records_written() const;
  const std::string& path() const { return path_; }

 private:
  AccessTraceWriter(std::string path, std::FILE* file, std::string source);
  void write_header_locked();
  void write_locked(const std::vector<AccessRecord>& chunk);

  const std::string path_;
  mutable std::mutex mutex_;
  std::FILE* file_ = nullptr;
  AccessTraceInfo info_;
  bool header_written_ = false;
  uint64_t next_seq_ = 0;
  uint64_t written_ = 0;
  std::map<uint64_t, std::vector<AccessRecord>> pending_;  // by first seq
  Status status_;
};

// Reads a trace; errors name the file and line (bad version, missing column
// line, a malformed field, seq out of order).
Expected<AccessTrace> read_access_trace(const std::string& path);

}  // namespace outcore
