#include "core/cache/access_trace.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string_view>
#include <utility>

#include "core/io/text_line_reader.h"

namespace outcore {
namespace {

constexpr const char* kColumns = "seq,brick,bytes,reserved_bytes,build_seconds,outcome";
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
    std::fprintf(file_, "%llu,%u,%llu,%llu,%.17g,%s\n", static_cast<unsigned long long>(r.seq), r.brick,
                 static_cast<unsigned long long>(r.bytes), static_cast<unsigned long long>(r.reserved_bytes),
                 r.build_seconds, access_outcome_name(r.outcome));
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
}  // namespace

Expected<AccessTrace> read_access_trace(const std::string& path) {
  TextLineReader reader;
  OUTCORE_RETURN_IF_ERROR(reader.open(path));
  AccessTrace trace;
  std::string_view line;
  bool saw_version = false, saw_columns = false;
  bool has_pending_hint = false;
  std::vector<uint32_t> pending_hint;
  uint64_t total_bytes = 0;  // of every record's bytes and reserved_bytes, <= kMaxTraceBytes
  const auto where = [&] { return path + ":" + std::to_string(reader.line_number()) + ": "; };
  while (reader.next_line(line)) {
    line = trim(line);
    if (line.empty()) continue;
    if (line.front() == '#') {
      std::string_view body = trim(line.substr(1));
      if (!saw_version) {
        constexpr std::string_view kPrefix = "outcore brick access trace, version ";
        if (body.substr(0, kPrefix.size()) != kPrefix)
          return invalid_argument(where() + "not an outcore access trace (the first line must be '# " +
                                  std::string(kPrefix) + std::to_string(kAccessTraceVersion) + "')");
        int version = 0;
        if (!parse_unsigned(body.substr(kPrefix.size()), version) || version < kOldestAccessTraceVersion ||
            version > kAccessTraceVersion)
          return failed_precondition(
              where() + "access trace version '" + std::string(body.substr(kPrefix.size())) +
              "' is not supported (this build reads versions " + std::to_string(kOldestAccessTraceVersion) +
              " to " + std::to_string(kAccessTraceVersion) + ")");
        saw_version = true;
        continue;
      }
      const auto colon = body.find(':');
      if (colon == std::string_view::npos) continue;  // a free comment
      const std::string_view key = trim(body.substr(0, colon));
      const std::string_view value = trim(body.substr(colon + 1));
      if (key == "hint") {
        pending_hint.clear();
        has_pending_hint = true;
        for (std::string_view rest = value; !rest.empty();) {
          const auto space = rest.find(' ');
          const std::string_view item = rest.substr(0, space);
          uint32_t brick = 0;
          if (!parse_unsigned(item, brick))
            return invalid_argument(where() + "bad brick id '" + std::string(item) + "' in a hint");
          // Policies index arrays by brick id: an absurd id must not allocate.
          const uint32_t limit = trace.info.bricks != 0 ? trace.info.bricks : kMaxUnlabelledBrickId;
          if (brick >= limit)
            return invalid_argument(where() + "brick " + std::to_string(brick) +
                                    " in a hint is beyond the trace's " + std::to_string(limit) + " bricks");
          pending_hint.push_back(brick);
          rest = space == std::string_view::npos ? std::string_view{} : trim(rest.substr(space + 1));
        }
        continue;
      }
      if (key == "policy") trace.info.policy = value;
      if (key == "builder") trace.info.builder = value;
      if (key == "source") trace.info.source = value;
      if (key == "budget_bytes" && !parse_unsigned(value, trace.info.budget_bytes))
        return invalid_argument(where() + "budget_bytes '" + std::string(value) + "' is not a byte count");
      if (key == "bricks" && !parse_unsigned(value, trace.info.bricks))
        return invalid_argument(where() + "bricks '" + std::string(value) + "' is not a count");
      continue;
    }
    if (!saw_version)
      return invalid_argument(where() +
                              "not an outcore access trace (no '# outcore brick access trace' line)");
    if (!saw_columns) {
      if (line != kColumns)
        return invalid_argument(where() + "expected the column line '" + std::string(kColumns) + "'");
      saw_columns = true;
      continue;
    }
    std::string_view fields[6];
    std::size_t count = 0;
    for (std::string_view rest = line;; ++count) {
      const auto comma = rest.find(',');
      if (count < 6) fields[count] = rest.substr(0, comma);
      if (comma == std::string_view::npos) {
        ++count;
        break;
      }
      rest.remove_prefix(comma + 1);
    }
    if (count != 6) return invalid_argument(where() + "expected 6 fields, found " + std::to_string(count));
    AccessRecord r;
    if (!parse_unsigned(fields[0], r.seq))
      return invalid_argument(where() + "bad seq '" + std::string(fields[0]) + "'");
    if (r.seq != trace.records.size())
      return invalid_argument(where() + "seq " + std::to_string(r.seq) + " out of order (expected " +
                              std::to_string(trace.records.size()) + ")");
    if (!parse_unsigned(fields[1], r.brick))
      return invalid_argument(where() + "bad brick id '" + std::string(fields[1]) + "'");
    if (!parse_unsigned(fields[2], r.bytes))
      return invalid_argument(where() + "bad bytes '" + std::string(fields[2]) + "'");
    if (!parse_unsigned(fields[3], r.reserved_bytes))
      return invalid_argument(where() + "bad reserved_bytes '" + std::string(fields[3]) + "'");
    // Each term is checked before the sum, so neither it nor the sum wraps.
    for (const auto& [name, value] :
         {std::pair{"bytes", r.bytes}, std::pair{"reserved_bytes", r.reserved_bytes}}) {
      if (value > kMaxTraceBytes - total_bytes) {
        return invalid_argument(
            where() + std::string(name) + " " + std::to_string(value) +
            (value > kMaxTraceBytes ? " is more than " : " brings the trace's byte counts to more than ") +
            std::to_string(kMaxTraceBytes) + " (2^62), beyond any real cache");
      }
      total_bytes += value;
    }
    if (parse_real(fields[4], r.build_seconds) != NumberParse::kOk || !std::isfinite(r.build_seconds) ||
        r.build_seconds < 0)
      return invalid_argument(where() + "bad build_seconds '" + std::string(fields[4]) + "'");
    if (fields[5] == "hit")
      r.outcome = AccessOutcome::kHit;
    else if (fields[5] == "miss")
      r.outcome = AccessOutcome::kMiss;
    else if (fields[5] == "wait")
      r.outcome = AccessOutcome::kWait;
    else if (fields[5] == "load")
      r.outcome = AccessOutcome::kLoad;
    else
      return invalid_argument(where() + "outcome '" + std::string(fields[5]) +
                              "' is not hit, miss, wait or load");
    if (trace.info.bricks != 0 && r.brick >= trace.info.bricks)
      return invalid_argument(where() + "brick " + std::to_string(r.brick) + " is beyond the trace's " +
                              std::to_string(trace.info.bricks) + " bricks");
    if (has_pending_hint) {
      r.has_hint = true;
      r.hint = std::move(pending_hint);
      pending_hint = {};
      has_pending_hint = false;
    }
    trace.records.push_back(std::move(r));
  }
  OUTCORE_RETURN_IF_ERROR(reader.status());
  if (!saw_version) return invalid_argument(path + ": empty file, not an outcore access trace");
  if (!saw_columns) return invalid_argument(path + ": no column line '" + std::string(kColumns) + "'");
  return trace;
}

}  // namespace outcore
