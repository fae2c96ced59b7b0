#include "core/gen/indexed_mesh.h"

#include <bit>

namespace outcore {

namespace {

constexpr uint32_t kMaxIndex = 0xFFFFFFFEu;  // table entries store index + 1

uint64_t hash_bits(const Vec3f& v) {
  uint64_t h = (static_cast<uint64_t>(std::bit_cast<uint32_t>(v.x)) << 32) | std::bit_cast<uint32_t>(v.y);
  h ^= static_cast<uint64_t>(std::bit_cast<uint32_t>(v.z)) * 0x9e3779b97f4a7c15ull;
  h ^= h >> 31;  // splitmix64 finaliser
  h *= 0xbf58476d1ce4e5b9ull;
  h ^= h >> 27;
  h *= 0x94d049bb133111ebull;
  h ^= h >> 31;
  return h;
}

bool same_bits(const Vec3f& a, const Vec3f& b) {
  return std::bit_cast<uint32_t>(a.x) == std::bit_cast<uint32_t>(b.x) &&
         std::bit_cast<uint32_t>(a.y) == std::bit_cast<uint32_t>(b.y) &&
         std::bit_cast<uint32_t>(a.z) == std::bit_cast<uint32_t>(b.z);
}

}  // namespace

void IndexedMeshBuilder::rehash(std::size_t capacity) {
  table_.assign(capacity, 0);
  const std::size_t mask = capacity - 1;
  for (std::size_t i = 0; i < mesh_.vertices.size(); ++i) {
    std::size_t slot = hash_bits(mesh_.vertices[i]) & mask;
    while (table_[slot] != 0) slot = (slot + 1) & mask;
    table_[slot] = static_cast<uint32_t>(i + 1);
  }
}

uint32_t IndexedMeshBuilder::index_of(const Vec3f& v) {
  // Keep the load factor at most 1/2.
  if (2 * (mesh_.vertices.size() + 1) > table_.size()) rehash(table_.empty() ? 1024 : 2 * table_.size());
  const std::size_t mask = table_.size() - 1;
  std::size_t slot = hash_bits(v) & mask;
  while (table_[slot] != 0) {
    const uint32_t index = table_[slot] - 1;
    if (same_bits(mesh_.vertices[index], v)) return index;
    slot = (slot + 1) & mask;
  }
  const auto index = static_cast<uint32_t>(mesh_.vertices.size());
  mesh_.vertices.push_back(v);
  table_[slot] = index + 1;
  return index;
}

Status IndexedMeshBuilder::add(const Triangle& t) {
  if (mesh_.vertices.size() + 3 > kMaxIndex || mesh_.triangles.size() >= kMaxIndex) {
    return resource_exhausted("mesh has more than " + std::to_string(kMaxIndex) + " vertices or triangles");
  }
  mesh_.triangles.push_back({index_of(t.v0), index_of(t.v1), index_of(t.v2)});
  return Status::Ok();
}

IndexedMesh IndexedMeshBuilder::finish() {
  std::vector<uint32_t>().swap(table_);
  mesh_.vertices.shrink_to_fit();
  mesh_.triangles.shrink_to_fit();
  IndexedMesh out = std::move(mesh_);
  mesh_ = {};
  return out;
}

}  // namespace outcore
