#include "core/io/vertex_spill.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>

#include "core/util/cancellation.h"

namespace outcore {

namespace {

constexpr std::size_t kKiB = 1024;
constexpr std::size_t kMiB = 1024 * kKiB;
// Below this an allowance is raised to it: the passes need a few buffers, and
// smaller ones spend their time creating files and in tiny reads and writes.
constexpr uint64_t kMinAllowanceBytes = 256 * kKiB;

// A corner with its vertex's position, waiting to be put back in triangle order.
struct ResolvedCorner {
  uint32_t triangle;
  uint32_t corner;
  Vec3f position;
};
static_assert(sizeof(ResolvedCorner) == 20, "resolved corners are stored packed");
static_assert(sizeof(SpillingFaceResolver::CornerRef) == 16, "corner refs are stored packed");

struct ByVertex {
  uint64_t operator()(const SpillingFaceResolver::CornerRef& r) const { return r.vertex; }
};
struct ByTriangleCorner {
  uint64_t operator()(const ResolvedCorner& r) const { return uint64_t{r.triangle} << 2 | r.corner; }
};

Status check_cancel() {
  return cancel_requested() ? cancelled("interrupted") : Status::Ok();
}

// Reads a file of fixed-size records sequentially through one buffer.
template <class Record>
class RecordReader {
 public:
  RecordReader() = default;
  ~RecordReader() {
    if (fd_ >= 0) ::close(fd_);
  }
  RecordReader(const RecordReader&) = delete;
  RecordReader& operator=(const RecordReader&) = delete;

  Status open(const std::string& path, std::size_t buffer_records) {
    path_ = path;
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) return io_error_from_errno("cannot open " + path);
    posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
    buffer_.resize(std::max<std::size_t>(buffer_records, 1));
    return Status::Ok();
  }
  // False at the end of the file or on an error (then status() says which).
  bool next(Record& record) {
    if (next_ == filled_ && !refill()) return false;
    record = buffer_[next_++];
    return true;
  }
  const Status& status() const { return status_; }

 private:
  bool refill() {
    next_ = filled_ = 0;
    std::size_t bytes = 0;
    char* data = reinterpret_cast<char*>(buffer_.data());
    const std::size_t capacity = buffer_.size() * sizeof(Record);
    while (bytes < capacity) {
      const ssize_t got = ::read(fd_, data + bytes, capacity - bytes);
      if (got < 0) {
        if (errno == EINTR) continue;
        status_ = io_error_from_errno("cannot read " + path_);
        return false;
      }
      if (got == 0) break;
      bytes += static_cast<std::size_t>(got);
    }
    if (bytes % sizeof(Record) != 0) {
      status_ = data_loss(path_ + " ends in a partial record");
      return false;
    }
    filled_ = bytes / sizeof(Record);
    return filled_ > 0;
  }

  std::string path_;
  int fd_ = -1;
  std::vector<Record> buffer_;
  std::size_t next_ = 0, filled_ = 0;
  Status status_;
};

// Sorts records by key and writes them to a new run file; clears records.
template <class Record, class Key>
Status write_sorted_run(std::vector<Record>& records, Key key, const std::string& path) {
  OUTCORE_RETURN_IF_ERROR(check_cancel());
  std::sort(records.begin(), records.end(),
            [key](const Record& a, const Record& b) { return key(a) < key(b); });
  RecordWriter<Record> run;
  OUTCORE_RETURN_IF_ERROR(run.create(path, 1));
  OUTCORE_RETURN_IF_ERROR(run.add_all(records));
  records.clear();
  return run.close();
}

void remove_files(const std::vector<std::string>& paths) {
  for (const std::string& path : paths) ::unlink(path.c_str());
}

// Merges sorted runs (at most fan_in of them) and calls emit(record) in key
// order; the run files are removed afterwards.
template <class Record, class Key, class Emit>
Status merge_runs(const std::vector<std::string>& runs, Key key, std::size_t buffer_records, Emit&& emit) {
  std::vector<RecordReader<Record>> readers(runs.size());
  std::vector<Record> heads(runs.size());
  // A min-heap of run indices by their head's key.
  std::vector<std::size_t> heap;
  heap.reserve(runs.size());
  const auto later = [&](std::size_t a, std::size_t b) { return key(heads[a]) > key(heads[b]); };
  for (std::size_t r = 0; r < runs.size(); ++r) {
    OUTCORE_RETURN_IF_ERROR(readers[r].open(runs[r], buffer_records));
    if (readers[r].next(heads[r])) {
      heap.push_back(r);
    } else {
      OUTCORE_RETURN_IF_ERROR(readers[r].status());
    }
  }
  std::make_heap(heap.begin(), heap.end(), later);
  uint64_t emitted = 0;
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    const std::size_t r = heap.back();
    OUTCORE_RETURN_IF_ERROR(emit(heads[r]));
    if (readers[r].next(heads[r])) {
      std::push_heap(heap.begin(), heap.end(), later);
    } else {
      OUTCORE_RETURN_IF_ERROR(readers[r].status());
      heap.pop_back();
    }
    if (++emitted % (std::size_t{1} << 20) == 0) OUTCORE_RETURN_IF_ERROR(check_cancel());
  }
  readers.clear();
  remove_files(runs);
  return Status::Ok();
}

// Merges groups of fan_in runs into longer runs until at most fan_in are left.
template <class Record, class Key, class NextFile>
Status reduce_runs(std::vector<std::string>& runs, Key key, const SpillingFaceResolver::Plan& plan,
                   NextFile&& next_file) {
  const std::size_t buffer_records = plan.merge_bytes / sizeof(Record);
  while (runs.size() > plan.fan_in) {
    std::vector<std::string> longer;
    for (std::size_t first = 0; first < runs.size(); first += plan.fan_in) {
      const std::size_t last = std::min(runs.size(), first + plan.fan_in);
      const std::vector<std::string> group(runs.begin() + static_cast<std::ptrdiff_t>(first),
                                           runs.begin() + static_cast<std::ptrdiff_t>(last));
      if (group.size() == 1) {
        longer.push_back(group.front());
        continue;
      }
      RecordWriter<Record> out;
      OUTCORE_RETURN_IF_ERROR(out.create(next_file(), plan.stream_bytes / sizeof(Record)));
      OUTCORE_RETURN_IF_ERROR(
          merge_runs<Record>(group, key, buffer_records, [&](const Record& r) { return out.add(r); }));
      OUTCORE_RETURN_IF_ERROR(out.close());
      longer.push_back(out.path());
    }
    runs = std::move(longer);
  }
  return Status::Ok();
}

}  // namespace

SpillingFaceResolver::Plan SpillingFaceResolver::Plan::for_allowance(uint64_t memory_bytes) {
  const auto allowance = static_cast<std::size_t>(std::max(memory_bytes, kMinAllowanceBytes));
  Plan plan{};
  // Half for a sort run; a quarter for the merge's read buffers (64 KiB each,
  // so that a merge reads in large requests, up to 64 runs at once); the rest
  // for the sequential vertex and triangle streams.
  plan.run_bytes = allowance / 2;
  plan.fan_in = std::clamp<std::size_t>(allowance / 4 / (64 * kKiB), 2, 64);
  plan.merge_bytes = std::max<std::size_t>(4 * kKiB, allowance / 4 / plan.fan_in);
  plan.stream_bytes = std::clamp<std::size_t>(allowance / 16, 4 * kKiB, kMiB);
  return plan;
}

Status SpilledTriangles::stream(TriangleSink& sink) const {
  constexpr std::size_t kBatchBytes = TriangleBatcher::kBatchSize * sizeof(Triangle);
  const std::size_t chunk_bytes = std::max<std::size_t>(1, read_bytes_ / kBatchBytes) * kBatchBytes;
  uint64_t streamed = 0;
  OUTCORE_RETURN_IF_ERROR(read_file_chunks(
      path_, sizeof(Triangle), chunk_bytes, [&](const char* data, std::size_t bytes) -> Status {
        // The chunk is a whole number of triangles, and Triangle is plain floats.
        const std::span<const Triangle> all(reinterpret_cast<const Triangle*>(data),
                                            bytes / sizeof(Triangle));
        for (std::size_t first = 0; first < all.size(); first += TriangleBatcher::kBatchSize) {
          OUTCORE_RETURN_IF_ERROR(
              sink.consume(all.subspan(first, std::min(TriangleBatcher::kBatchSize, all.size() - first))));
        }
        streamed += all.size();
        return Status::Ok();
      }));
  if (streamed != count_) {
    return data_loss(path_ + " holds " + std::to_string(streamed) + " triangles; " + std::to_string(count_) +
                     " were written");
  }
  return Status::Ok();
}

SpillingFaceResolver::SpillingFaceResolver(std::string input, uint64_t memory_bytes, std::string temp_dir)
    : input_(std::move(input)),
      temp_dir_(temp_dir.empty() ? default_temp_directory() : std::move(temp_dir)),
      plan_(Plan::for_allowance(memory_bytes)),
      run_records_(std::max<std::size_t>(plan_.run_bytes / sizeof(CornerRef), 3)) {}

Status SpillingFaceResolver::begin() {
  directory_ = std::make_unique<TemporaryDirectory>();
  OUTCORE_RETURN_IF_ERROR(directory_->create(temp_dir_ + "/vertex-spill-"));
  corners_.reserve(run_records_);
  return vertices_.create(next_file("vertices"), plan_.stream_bytes / sizeof(Vec3f));
}

std::string SpillingFaceResolver::next_file(const char* kind) {
  return directory_->path() + "/" + kind + "-" + std::to_string(file_serial_++) + ".bin";
}

Status SpillingFaceResolver::too_many_triangles() const {
  return invalid_argument(input_ + ": more than " + std::to_string(kMaxTrianglesPerInput - 1) +
                          " triangles; primitive ids are 32-bit, split the input");
}

Status SpillingFaceResolver::write_corner_run() {
  corner_runs_.push_back(next_file("corners"));
  return write_sorted_run(corners_, ByVertex{}, corner_runs_.back());
}

Expected<std::unique_ptr<SpilledTriangles>> SpillingFaceResolver::finish() {
  std::unique_ptr<SpilledTriangles> triangles;
  const Status status = resolve(triangles);
  if (!status.ok()) {
    directory_.reset();  // removes every temporary file now, not at the source's end
    return status.with_context(input_ + ": resolving faces out of core");
  }
  return triangles;
}

Status SpillingFaceResolver::resolve(std::unique_ptr<SpilledTriangles>& out) {
  if (!directory_) return internal_error("SpillingFaceResolver::finish() without begin()");
  const std::string vertex_path = vertices_.path();
  OUTCORE_RETURN_IF_ERROR(vertices_.close());
  if (!corners_.empty()) OUTCORE_RETURN_IF_ERROR(write_corner_run());
  corners_ = {};

  // Join: corners in vertex order meet the vertex file read front to back.
  const auto next_merge_file = [this] { return next_file("merged"); };
  OUTCORE_RETURN_IF_ERROR(reduce_runs<CornerRef>(corner_runs_, ByVertex{}, plan_, next_merge_file));
  std::vector<ResolvedCorner> resolved;
  resolved.reserve(std::max<std::size_t>(plan_.run_bytes / sizeof(ResolvedCorner), 1));
  std::vector<std::string> resolved_runs;
  {
    RecordReader<Vec3f> vertices;
    OUTCORE_RETURN_IF_ERROR(vertices.open(vertex_path, plan_.stream_bytes / sizeof(Vec3f)));
    Vec3f position;
    uint64_t next_vertex = 0;  // index of the vertex the reader returns next
    const auto join = [&](const CornerRef& ref) -> Status {
      while (next_vertex <= ref.vertex) {
        if (!vertices.next(position)) {
          OUTCORE_RETURN_IF_ERROR(vertices.status());
          return internal_error("corner of triangle " + std::to_string(ref.triangle) + " uses vertex " +
                                std::to_string(ref.vertex) + " of " + std::to_string(vertex_count_));
        }
        ++next_vertex;
      }
      resolved.push_back({ref.triangle, ref.corner, position});
      if (resolved.size() < resolved.capacity()) return Status::Ok();
      resolved_runs.push_back(next_file("resolved"));
      return write_sorted_run(resolved, ByTriangleCorner{}, resolved_runs.back());
    };
    OUTCORE_RETURN_IF_ERROR(
        merge_runs<CornerRef>(corner_runs_, ByVertex{}, plan_.merge_bytes / sizeof(CornerRef), join));
  }
  ::unlink(vertex_path.c_str());
  if (!resolved.empty()) {
    resolved_runs.push_back(next_file("resolved"));
    OUTCORE_RETURN_IF_ERROR(write_sorted_run(resolved, ByTriangleCorner{}, resolved_runs.back()));
  }
  resolved = {};

  // Back in (triangle, corner) order, every corner exactly once.
  OUTCORE_RETURN_IF_ERROR(
      reduce_runs<ResolvedCorner>(resolved_runs, ByTriangleCorner{}, plan_, next_merge_file));
  RecordWriter<Triangle> triangles;
  OUTCORE_RETURN_IF_ERROR(
      triangles.create(next_file("triangles"), plan_.stream_bytes / sizeof(Triangle) + 1));
  Triangle triangle;
  uint64_t next_slot = 0;  // 3 * triangle + corner expected next
  const auto assemble = [&](const ResolvedCorner& r) -> Status {
    if (r.triangle != next_slot / 3 || r.corner != next_slot % 3) {
      return internal_error("corner " + std::to_string(r.corner) + " of triangle " +
                            std::to_string(r.triangle) + " out of sequence");
    }
    (r.corner == 0 ? triangle.v0 : r.corner == 1 ? triangle.v1 : triangle.v2) = r.position;
    return ++next_slot % 3 == 0 ? triangles.add(triangle) : Status::Ok();
  };
  OUTCORE_RETURN_IF_ERROR(merge_runs<ResolvedCorner>(resolved_runs, ByTriangleCorner{},
                                                     plan_.merge_bytes / sizeof(ResolvedCorner), assemble));
  if (next_slot != 3 * triangle_count_) {
    return internal_error(std::to_string(next_slot) + " corners resolved of " +
                          std::to_string(3 * triangle_count_));
  }
  const std::string triangle_path = triangles.path();
  OUTCORE_RETURN_IF_ERROR(triangles.close());
  out = std::make_unique<SpilledTriangles>(std::move(directory_), triangle_path, triangle_count_,
                                           plan_.stream_bytes);
  return Status::Ok();
}

}  // namespace outcore
