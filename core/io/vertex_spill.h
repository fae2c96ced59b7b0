// Face resolvers for the OBJ and PLY readers (not the city generator's
// core/gen/indexed_mesh.h). A reader parses vertex positions and triangles as
// vertex index triples (already checked to be in range) into one of two
// resolvers with the same inline interface, chosen per file:
//
// - InMemoryFaceResolver holds the positions (12 B a vertex) and hands each
//   triangle to the sink as soon as it is read. Fastest; used when the
//   vertices fit in the reader's allowance (SourceOptions::vertex_memory_bytes).
// - SpillingFaceResolver keeps memory within the allowance whatever the file's
//   size, because faces index vertices at random: positions go to a file in
//   index order, and every triangle corner (vertex, triangle, corner) to
//   external sort runs. finish() merges the corners by vertex, joins them with
//   the vertex file in one sequential read, sorts the resolved corners back by
//   (triangle, corner) and writes the triangles in order to a file, which
//   SpilledTriangles streams as often as the source is streamed. All
//   temporary files live in one private directory, removed when the last
//   owner goes (also on error).
//
// Both yield the same triangles bit for bit, in the same order: positions are
// copied, never recomputed.
//
// Thread-safety: a resolver is used by one thread at a time; SpilledTriangles::
// stream() is const and may run in several threads at once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/io/triangle_source.h"
#include "core/util/buffered_file.h"
#include "core/util/temporary_directory.h"

namespace outcore {

// Triangles have 32-bit primitive ids; this many or more cannot be packed.
inline constexpr uint64_t kMaxTrianglesPerInput = 0xffffffffull;

class InMemoryFaceResolver {
 public:
  explicit InMemoryFaceResolver(TriangleSink& sink) : batcher_(sink) {}

  void reserve_vertices(uint64_t count) { vertices_.reserve(static_cast<std::size_t>(count)); }
  Status add_vertex(const Vec3f& position) {
    vertices_.push_back(position);
    return Status::Ok();
  }
  uint64_t vertex_count() const { return vertices_.size(); }
  Status add_triangle(uint64_t a, uint64_t b, uint64_t c) {
    return batcher_.add(Triangle{vertices_[a], vertices_[b], vertices_[c]});
  }
  Status finish() { return batcher_.finish(); }

 private:
  std::vector<Vec3f> vertices_;
  TriangleBatcher batcher_;
};

// Appends fixed-size records to a new file through one buffer of its own
// (the file writer below it is unbuffered, so each flush is one write(2)).
template <class Record>
class RecordWriter {
 public:
  Status create(const std::string& path, std::size_t buffer_records) {
    buffer_.clear();
    buffer_.reserve(buffer_records);
    limit_ = buffer_records;
    return file_.create(path, /*buffer_bytes=*/0);
  }
  Status add(const Record& record) {
    buffer_.push_back(record);
    return buffer_.size() == limit_ ? flush() : Status::Ok();
  }
  Status add_all(std::span<const Record> records) {
    OUTCORE_RETURN_IF_ERROR(flush());
    return file_.append(records.data(), records.size_bytes());
  }
  // Flushes, closes and releases the buffer.
  Status close() {
    OUTCORE_RETURN_IF_ERROR(flush());
    buffer_ = {};
    return file_.close(/*sync=*/false);
  }
  const std::string& path() const { return file_.path(); }

 private:
  Status flush() {
    if (buffer_.empty()) return Status::Ok();
    const Status status = file_.append(buffer_.data(), buffer_.size() * sizeof(Record));
    buffer_.clear();
    return status;
  }

  BufferedFileWriter file_;
  std::vector<Record> buffer_;
  std::size_t limit_ = 1;
};

// The resolved triangles of a spilled mesh, in primitive-id order, in a file
// that is removed with this object.
class SpilledTriangles {
 public:
  SpilledTriangles(std::unique_ptr<TemporaryDirectory> directory, std::string path, uint64_t count,
                   std::size_t read_bytes)
      : directory_(std::move(directory)), path_(std::move(path)), count_(count), read_bytes_(read_bytes) {}

  uint64_t triangle_count() const { return count_; }
  // Hands the triangles to sink in batches of TriangleBatcher::kBatchSize.
  Status stream(TriangleSink& sink) const;

 private:
  std::unique_ptr<TemporaryDirectory> directory_;
  std::string path_;
  uint64_t count_;
  std::size_t read_bytes_;
};

class SpillingFaceResolver {
 public:
  // One triangle corner waiting for its vertex's position.
  struct CornerRef {
    uint64_t vertex;
    uint32_t triangle;
    uint32_t corner;
  };

  // input names the file in messages; memory_bytes bounds the buffers (runs,
  // merge fan-in); temporary files go into a new directory under temp_dir.
  SpillingFaceResolver(std::string input, uint64_t memory_bytes, std::string temp_dir);

  // Creates the temporary directory and the vertex file; call before adding.
  Status begin();
  void reserve_vertices(uint64_t) {}
  Status add_vertex(const Vec3f& position) {
    ++vertex_count_;
    return vertices_.add(position);
  }
  uint64_t vertex_count() const { return vertex_count_; }
  Status add_triangle(uint64_t a, uint64_t b, uint64_t c) {
    if (triangle_count_ + 1 >= kMaxTrianglesPerInput) return too_many_triangles();
    const auto triangle = static_cast<uint32_t>(triangle_count_++);
    corners_.push_back({a, triangle, 0});
    corners_.push_back({b, triangle, 1});
    corners_.push_back({c, triangle, 2});
    return corners_.size() + 3 > run_records_ ? write_corner_run() : Status::Ok();
  }
  // Resolves every corner; the resolver is spent afterwards.
  Expected<std::unique_ptr<SpilledTriangles>> finish();

  // How the allowance is shared (public for tests).
  struct Plan {
    std::size_t run_bytes;     // one in-memory sort run
    std::size_t fan_in;        // runs merged at once
    std::size_t merge_bytes;   // read buffer per merged run
    std::size_t stream_bytes;  // each sequential reader or writer
    static Plan for_allowance(uint64_t memory_bytes);
  };

 private:
  Status too_many_triangles() const;
  Status write_corner_run();
  Status resolve(std::unique_ptr<SpilledTriangles>& out);
  std::string next_file(const char* kind);

  std::string input_;
  std::string temp_dir_;
  Plan plan_;
  std::size_t run_records_;
  std::unique_ptr<TemporaryDirectory> directory_;
  uint64_t file_serial_ = 0;
  RecordWriter<Vec3f> vertices_;
  uint64_t vertex_count_ = 0;
  std::vector<CornerRef> corners_;
  std::vector<std::string> corner_runs_;
  uint64_t triangle_count_ = 0;
};

// What an OBJ or PLY source keeps between stream() calls, and the choice of
// resolver: stream<Pass>() runs Pass<Resolver>(path, resolver).run() (one
// pass of the reader over the file) into an InMemoryFaceResolver straight to
// the sink when the vertices fit, else, once, into a SpillingFaceResolver
// whose triangles this and every later call then stream.
class ResolvedFaces {
 public:
  template <template <class> class Pass>
  Status stream(const std::string& path, const SourceOptions& options, bool vertices_fit,
                uint64_t vertices_to_reserve, TriangleSink& sink) {
    if (spilled_ == nullptr) {
      if (vertices_fit) {
        // On the heap: the batcher's buffer is too large for a small thread stack.
        auto faces = std::make_unique<InMemoryFaceResolver>(sink);
        faces->reserve_vertices(vertices_to_reserve);
        OUTCORE_RETURN_IF_ERROR(Pass<InMemoryFaceResolver>(path, *faces).run());
        return faces->finish();
      }
      SpillingFaceResolver faces(path, options.vertex_memory_bytes, options.temp_dir);
      OUTCORE_RETURN_IF_ERROR(faces.begin());
      OUTCORE_RETURN_IF_ERROR(Pass<SpillingFaceResolver>(path, faces).run());
      OUTCORE_ASSIGN_OR_RETURN(spilled_, faces.finish());
    }
    return spilled_->stream(sink);
  }

 private:
  std::unique_ptr<SpilledTriangles> spilled_;
};

}  // namespace outcore
