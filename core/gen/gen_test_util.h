// Test helpers for the generator tests (core/gen/*_test.cpp; the file reader
// tests use them too): a spec's triangles, checks of closed and consistently
// oriented meshes, a sink that fails on purpose.
//
// Thread-safety: plain functions and test-local objects.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/gen/generator_factory.h"
#include "core/io/triangle_source.h"

namespace outcore::gen_test {

inline std::vector<Triangle> collect_spec(const std::string& spec) {
  auto source = make_generator(spec);
  EXPECT_TRUE(source.ok()) << spec << ": " << source.status().to_string();
  if (!source.ok()) return {};
  auto tris = read_all(**source);
  EXPECT_TRUE(tris.ok()) << spec << ": " << tris.status().to_string();
  return tris.ok() ? std::move(tris).value() : std::vector<Triangle>{};
}

using VertexKey = std::array<uint32_t, 3>;
inline VertexKey key_of(const Vec3f& v) {
  return {std::bit_cast<uint32_t>(v.x), std::bit_cast<uint32_t>(v.y), std::bit_cast<uint32_t>(v.z)};
}

// Closed and consistently oriented: vertices identified by their exact bits,
// every directed edge used once and its reverse used once (so every undirected
// edge is shared by exactly two triangles, with opposite orientations), no
// triangle with repeated vertices. Returns an empty string or the first problem.
inline std::string closed_oriented_problem(const std::vector<Triangle>& tris) {
  std::map<VertexKey, uint32_t> ids;
  const auto id = [&](const Vec3f& v) {
    return ids.emplace(key_of(v), static_cast<uint32_t>(ids.size())).first->second;
  };
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    const uint32_t a = id(tris[t].v0), b = id(tris[t].v1), c = id(tris[t].v2);
    if (a == b || b == c || c == a) return "triangle " + std::to_string(t) + " repeats a vertex";
    for (const auto& e : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
      if (++directed[e] > 1)
        return "directed edge used twice (inconsistent winding) at triangle " + std::to_string(t);
    }
  }
  for (const auto& [e, n] : directed) {
    if (directed.find({e.second, e.first}) == directed.end()) {
      return "edge " + std::to_string(e.first) + "-" + std::to_string(e.second) +
             " has no opposite (open boundary)";
    }
  }
  return {};
}

inline Vec3d normal_of(const Triangle& t) {
  const Vec3d a(t.v0), b(t.v1), c(t.v2);
  return cross(b - a, c - a);
}
inline Vec3d centroid_of(const Triangle& t) {
  return (Vec3d(t.v0) + Vec3d(t.v1) + Vec3d(t.v2)) / 3.0;
}

// Fails with `status` on the `fail_at`-th batch (1-based); counts batches.
class FailingSink final : public TriangleSink {
 public:
  FailingSink(int fail_at, Status status) : fail_at_(fail_at), status_(std::move(status)) {}
  Status consume(std::span<const Triangle>) override {
    return ++batches_ == fail_at_ ? status_ : Status::Ok();
  }
  int batches() const { return batches_; }

 private:
  int fail_at_;
  Status status_;
  int batches_ = 0;
};

// stream() twice gives identical triangles; a sink error on the 2nd batch is
// returned unchanged and stops the stream.
inline void expect_restreamable_and_sink_errors_propagate(const std::string& spec) {
  SCOPED_TRACE(spec);
  auto source = make_generator(spec);
  ASSERT_TRUE(source.ok()) << source.status().to_string();
  auto first = read_all(**source);
  auto second = read_all(**source);
  ASSERT_TRUE(first.ok() && second.ok());
  EXPECT_EQ(*first, *second);
  ASSERT_GT(first->size(), 2 * TriangleBatcher::kBatchSize) << "need at least 3 batches for the sink test";

  FailingSink sink(2, cancelled("stop here, code 42"));
  const Status s = (*source)->stream(sink);
  EXPECT_EQ(s.code(), StatusCode::kCancelled);
  EXPECT_EQ(s.message(), "stop here, code 42");
  EXPECT_EQ(sink.batches(), 2);
}

}  // namespace outcore::gen_test
