// IndexedMesh: a triangle mesh held in memory as unique vertices plus index
// triples, welded by exact vertex bits (no tolerance), so that expanding it
// gives back exactly the triangles that went in, in the same order. Used where
// a generator must keep a mesh in memory and transform it many times (the
// city's base): each unique vertex is transformed once per copy instead of
// once per triangle corner, and it takes 12 B per vertex + 12 B per triangle
// instead of 36 B per triangle.
//
// IndexedMeshBuilder welds while triangles stream in, with an open-addressing
// hash table (4..8 B per unique vertex) that finish() releases.
//
// Thread-safety: IndexedMesh is a plain value; a builder is used by one thread.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/geometry/triangle.h"
#include "core/util/status.h"

namespace outcore {

struct IndexedMesh {
  std::vector<Vec3f> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;

  std::size_t triangle_count() const { return triangles.size(); }
  Triangle triangle(std::size_t k) const {
    const auto& t = triangles[k];
    return {vertices[t[0]], vertices[t[1]], vertices[t[2]]};
  }
  Aabb bounds() const {
    Aabb b;
    for (const Vec3f& v : vertices) b.extend(v);
    return b;
  }
};

class IndexedMeshBuilder {
 public:
  // Avoids regrowth when the triangle count is known in advance.
  void reserve_triangles(std::size_t n) { mesh_.triangles.reserve(n); }
  // Fails (RESOURCE_EXHAUSTED) only if the mesh exceeds 2^32 - 1 vertices or triangles.
  Status add(const Triangle& t);
  // What the builder holds now (mesh and welding table, by capacity).
  uint64_t memory_bytes() const {
    return mesh_.vertices.capacity() * sizeof(Vec3f) +
           mesh_.triangles.capacity() * sizeof(mesh_.triangles[0]) + table_.capacity() * sizeof(uint32_t);
  }
  // The welded mesh, capacity trimmed; the builder is empty afterwards.
  IndexedMesh finish();

 private:
  uint32_t index_of(const Vec3f& v);
  void rehash(std::size_t capacity);

  IndexedMesh mesh_;
  std::vector<uint32_t> table_;  // vertex index + 1; 0 = empty slot
};

}  // namespace outcore
