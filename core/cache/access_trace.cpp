#include "core/cache/access_trace.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string_view>
#include <utility>

#include "core/accel/brick_accel_factory.h"
#include "core/io/text_line_reader.h"

namespace outcore {
namespace {

constexpr const char* kColumns = "seq,brick,bytes,reserved_bytes,build_seconds,outcome,structure,rays";
// Versions 1 and 2 had no structure and rays.
constexpr const char* kColumnsBefore3 = "seq,brick,bytes,reserved_bytes,build_seconds,outcome";
constexpr std::size_t kMaxFields = 8;
constexpr std::size_t kFileBuffer = std::size_t{1} << 20;

template <class T>
bool parse_unsigned(std::string_view token, T& value) {
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  return ec == std::errc() && end == token.data() + token.size() && !token.empty();
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

}  // namespace

const char* access_outcome_name(AccessOutcome outcome) {
  switch (outcome) {
    case AccessOutcome::kHit: return "hit";
    case AccessOutcome::kMiss: return "miss";
    case AccessOutcome::kWait: return "wait";
    case AccessOutcome::kLoad: return "load";
  }
  return "?";
}

Expected<std::shared_ptr<AccessTraceWriter>> AccessTraceWriter::create(const std::string& path,
                                                                       std::string source) {
  std::FILE* file = std::fopen(path.c_str(), "w");
  if (file == nullptr) return io_error_from_errno("cannot create access trace " + path);
  return std::shared_ptr<AccessTraceWriter>(new AccessTraceWriter(path, file, std::move(source)));
}

AccessTraceWriter::AccessTraceWriter(std::string path, std::FILE* file, std::string source)
    : path_(std::move(path)), file_(file) {
  info_.source = std::move(source);
  std::setvbuf(file_, nullptr, _IOFBF, kFileBuffer);
}

AccessTraceWriter::~AccessTraceWriter() {
  (void)close();
}

void AccessTraceWriter::set_info(const std::string& policy, uint64_t budget_bytes, const std::string& builder,
                                 uint32_t bricks) {
  std::lock_guard lock(mutex_);
  info_.policy = policy;
  info_.budget_bytes = budget_bytes;
  info_.builder = builder;
  info_.bricks = bricks;
}

void AccessTraceWriter::write_header_locked() {
  if (header_written_) return;
  header_written_ = true;
  std::fprintf(file_, "# outcore brick access trace, version %d\n", kAccessTraceVersion);
  if (!info_.policy.empty()) std::fprintf(file_, "# policy: %s\n", info_.policy.c_str());
  if (info_.budget_bytes != 0)
    std::fprintf(file_, "# budget_bytes: %llu\n", static_cast<unsigned long long>(info_.budget_bytes));
  if (!info_.builder.empty()) std::fprintf(file_, "# builder: %s\n", info_.builder.c_str());
  if (info_.bricks != 0) std::fprintf(file_, "# bricks: %u\n", info_.bricks);
  if (!info_.source.empty()) std::fprintf(file_, "# source: %s\n", info_.source.c_str());
  std::fprintf(file_, "%s\n", kColumns);
}

void AccessTraceWriter::write_locked(const std::vector<AccessRecord>& chunk) {
  write_header_locked();
  for (const AccessRecord& r : chunk) {
    if (r.has_hint) {
      std::fputs("# hint:", file_);
      for (const uint32_t b : r.hint) std::fprintf(file_, " %u", b);
      std::fputc('\n', file_);
    }
    std::fprintf(file_, "%llu,%u,%llu,%llu,%.17g,%s,%s,%llu\n", static_cast<unsigned long long>(r.seq),
                 r.brick, static_cast<unsigned long long>(r.bytes),
                 static_cast<unsigned long long>(r.reserved_bytes), r.build_seconds,
                 access_outcome_name(r.outcome), r.structure.c_str(),
                 static_cast<unsigned long long>(r.rays));
  }
  written_ += chunk.size();
}

void AccessTraceWriter::append(std::vector<AccessRecord> chunk) {
  if (chunk.empty()) return;
  std::lock_guard lock(mutex_);
  if (file_ == nullptr) return;
  const uint64_t first = chunk.front().seq;
  pending_.emplace(first, std::move(chunk));
  while (!pending_.empty() && pending_.begin()->first == next_seq_) {
    write_locked(pending_.begin()->second);
    next_seq_ += pending_.begin()->second.size();
    pending_.erase(pending_.begin());
  }
}

Status AccessTraceWriter::close() {
  std::lock_guard lock(mutex_);
  if (file_ == nullptr) return status_;
  write_header_locked();
  for (const auto& [first, chunk] : pending_) write_locked(chunk);
  pending_.clear();
  const bool failed = std::ferror(file_) != 0;
  const int saved = errno;
  if (std::fclose(file_) != 0 || failed) {
    errno = failed ? saved : errno;
    status_ = io_error_from_errno("cannot write access trace " + path_);
  }
  file_ = nullptr;
  return status_;
}

uint64_t AccessTraceWriter::records_written() const {
  std::lock_guard lock(mutex_);
  return written_;
}

namespace {

// Brick ids allowed in a hint of a trace without a "bricks" line.
constexpr uint32_t kMaxUnlabelledBrickId = uint32_t{1} << 26;

bool parse_outcome(std::string_view name, AccessOutcome& outcome) {
  for (const AccessOutcome candidate :
       {AccessOutcome::kHit, AccessOutcome::kMiss, AccessOutcome::kWait, AccessOutcome::kLoad}) {
    if (name == access_outcome_name(candidate)) {
      outcome = candidate;
      return true;
    }
  }
  return false;
}

// read_access_trace's state: the trace so far, the hint waiting for its
// record, and the running byte total. Errors name the file and line.
class TraceReader {
 public:
  explicit TraceReader(const std::string& path) : path_(path) {}

  Expected<AccessTrace> read();

 private:
  std::string where() const { return path_ + ":" + std::to_string(reader_.line_number()) + ": "; }
  Status read_line(std::string_view line);
  Status read_comment(std::string_view body);
  Status read_version(std::string_view body);
  Status read_hint(std::string_view value);
  Status read_record(std::string_view line);
  // The comma-separated fields of a record line (6 before version 3, else 8).
  Status split_fields(std::string_view line, std::string_view (&fields)[kMaxFields]) const;
  // Each term is checked before the sum, so neither it nor the sum wraps.
  Status add_bytes(const char* name, uint64_t value);

  const std::string& path_;
  TextLineReader reader_;
  AccessTrace trace_;
  bool saw_version_ = false, saw_columns_ = false;
  int version_ = 0;
  bool has_pending_hint_ = false;
  std::vector<uint32_t> pending_hint_;
  uint64_t total_bytes_ = 0;  // of every record's bytes and reserved_bytes, <= kMaxTraceBytes
};

Expected<AccessTrace> TraceReader::read() {
  OUTCORE_RETURN_IF_ERROR(reader_.open(path_));
  std::string_view line;
  while (reader_.next_line(line)) {
    line = trim(line);
    if (!line.empty()) OUTCORE_RETURN_IF_ERROR(read_line(line));
  }
  OUTCORE_RETURN_IF_ERROR(reader_.status());
  if (!saw_version_) return invalid_argument(path_ + ": empty file, not an outcore access trace");
  if (!saw_columns_) return invalid_argument(path_ + ": no column line '" + std::string(kColumns) + "'");
  return std::move(trace_);
}

Status TraceReader::read_line(std::string_view line) {
  if (line.front() == '#') return read_comment(trim(line.substr(1)));
  if (!saw_version_)
    return invalid_argument(where() + "not an outcore access trace (no '# outcore brick access trace' line)");
  if (!saw_columns_) {
    const char* columns = version_ >= 3 ? kColumns : kColumnsBefore3;
    if (line != columns)
      return invalid_argument(where() + "expected the column line '" + std::string(columns) + "'");
    saw_columns_ = true;
    return Status::Ok();
  }
  return read_record(line);
}

Status TraceReader::read_version(std::string_view body) {
  constexpr std::string_view kPrefix = "outcore brick access trace, version ";
  if (body.substr(0, kPrefix.size()) != kPrefix)
    return invalid_argument(where() + "not an outcore access trace (the first line must be '# " +
                            std::string(kPrefix) + std::to_string(kAccessTraceVersion) + "')");
  if (!parse_unsigned(body.substr(kPrefix.size()), version_) || version_ < kOldestAccessTraceVersion ||
      version_ > kAccessTraceVersion)
    return failed_precondition(where() + "access trace version '" + std::string(body.substr(kPrefix.size())) +
                               "' is not supported (this build reads versions " +
                               std::to_string(kOldestAccessTraceVersion) + " to " +
                               std::to_string(kAccessTraceVersion) + ")");
  saw_version_ = true;
  return Status::Ok();
}

Status TraceReader::read_comment(std::string_view body) {
  if (!saw_version_) return read_version(body);
  const auto colon = body.find(':');
  if (colon == std::string_view::npos) return Status::Ok();  // a free comment
  const std::string_view key = trim(body.substr(0, colon));
  const std::string_view value = trim(body.substr(colon + 1));
  if (key == "hint") return read_hint(value);
  AccessTraceInfo& info = trace_.info;
  if (key == "policy") info.policy = value;
  if (key == "builder") info.builder = value;
  if (key == "source") info.source = value;
  if (key == "budget_bytes" && !parse_unsigned(value, info.budget_bytes))
    return invalid_argument(where() + "budget_bytes '" + std::string(value) + "' is not a byte count");
  if (key == "bricks" && !parse_unsigned(value, info.bricks))
    return invalid_argument(where() + "bricks '" + std::string(value) + "' is not a count");
  return Status::Ok();
}

Status TraceReader::read_hint(std::string_view value) {
  pending_hint_.clear();
  has_pending_hint_ = true;
  for (std::string_view rest = value; !rest.empty();) {
    const auto space = rest.find(' ');
    const std::string_view item = rest.substr(0, space);
    uint32_t brick = 0;
    if (!parse_unsigned(item, brick))
      return invalid_argument(where() + "bad brick id '" + std::string(item) + "' in a hint");
    // Policies index arrays by brick id: an absurd id must not allocate.
    const uint32_t limit = trace_.info.bricks != 0 ? trace_.info.bricks : kMaxUnlabelledBrickId;
    if (brick >= limit)
      return invalid_argument(where() + "brick " + std::to_string(brick) +
                              " in a hint is beyond the trace's " + std::to_string(limit) + " bricks");
    pending_hint_.push_back(brick);
    rest = space == std::string_view::npos ? std::string_view{} : trim(rest.substr(space + 1));
  }
  return Status::Ok();
}

Status TraceReader::split_fields(std::string_view line, std::string_view (&fields)[kMaxFields]) const {
  const std::size_t expected = version_ >= 3 ? 8 : 6;
  std::size_t count = 0;
  for (std::string_view rest = line;; ++count) {
    const auto comma = rest.find(',');
    if (count < kMaxFields) fields[count] = rest.substr(0, comma);
    if (comma == std::string_view::npos) {
      ++count;
      break;
    }
    rest.remove_prefix(comma + 1);
  }
  if (count != expected)
    return invalid_argument(where() + "expected " + std::to_string(expected) + " fields, found " +
                            std::to_string(count));
  return Status::Ok();
}

Status TraceReader::add_bytes(const char* name, uint64_t value) {
  if (value > kMaxTraceBytes - total_bytes_) {
    return invalid_argument(
        where() + std::string(name) + " " + std::to_string(value) +
        (value > kMaxTraceBytes ? " is more than " : " brings the trace's byte counts to more than ") +
        std::to_string(kMaxTraceBytes) + " (2^62), beyond any real cache");
  }
  total_bytes_ += value;
  return Status::Ok();
}

Status TraceReader::read_record(std::string_view line) {
  std::string_view fields[kMaxFields];
  OUTCORE_RETURN_IF_ERROR(split_fields(line, fields));
  AccessRecord r;
  if (!parse_unsigned(fields[0], r.seq))
    return invalid_argument(where() + "bad seq '" + std::string(fields[0]) + "'");
  if (r.seq != trace_.records.size())
    return invalid_argument(where() + "seq " + std::to_string(r.seq) + " out of order (expected " +
                            std::to_string(trace_.records.size()) + ")");
  if (!parse_unsigned(fields[1], r.brick))
    return invalid_argument(where() + "bad brick id '" + std::string(fields[1]) + "'");
  if (!parse_unsigned(fields[2], r.bytes))
    return invalid_argument(where() + "bad bytes '" + std::string(fields[2]) + "'");
  if (!parse_unsigned(fields[3], r.reserved_bytes))
    return invalid_argument(where() + "bad reserved_bytes '" + std::string(fields[3]) + "'");
  OUTCORE_RETURN_IF_ERROR(add_bytes("bytes", r.bytes));
  OUTCORE_RETURN_IF_ERROR(add_bytes("reserved_bytes", r.reserved_bytes));
  if (parse_real(fields[4], r.build_seconds) != NumberParse::kOk || !std::isfinite(r.build_seconds) ||
      r.build_seconds < 0)
    return invalid_argument(where() + "bad build_seconds '" + std::string(fields[4]) + "'");
  if (!parse_outcome(fields[5], r.outcome))
    return invalid_argument(where() + "outcome '" + std::string(fields[5]) +
                            "' is not hit, miss, wait or load");
  if (version_ >= 3) {
    r.structure = fields[6];
    if (!r.structure.empty() && brick_structure_index(r.structure) == kMaxBrickStructures)
      return invalid_argument(where() + "structure '" + r.structure + "' is not a brick structure");
    if (!parse_unsigned(fields[7], r.rays))
      return invalid_argument(where() + "bad rays '" + std::string(fields[7]) + "'");
  }
  if (trace_.info.bricks != 0 && r.brick >= trace_.info.bricks)
    return invalid_argument(where() + "brick " + std::to_string(r.brick) + " is beyond the trace's " +
                            std::to_string(trace_.info.bricks) + " bricks");
  if (has_pending_hint_) {
    r.has_hint = true;
    r.hint = std::move(pending_hint_);
    pending_hint_ = {};
    has_pending_hint_ = false;
  }
  trace_.records.push_back(std::move(r));
  return Status::Ok();
}

}  // namespace

Expected<AccessTrace> read_access_trace(const std::string& path) {
  return TraceReader(path).read();
}

}  // namespace outcore
