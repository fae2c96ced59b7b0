#include "core/proxy/proxy_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "core/proxy/proxy_grid.h"
#include "core/util/atomic_file.h"
#include "core/util/checksum.h"

namespace outcore {

namespace {

namespace fs = std::filesystem;

struct FrameRecord {
  double origin[3];
  double voxel_size;
  int32_t dims[3];
  int32_t pad;
  double margin;
};
static_assert(sizeof(FrameRecord) == 56);

struct LeafRecord {
  int32_t origin[3];
  int32_t pad;
  uint64_t words[8];
};
static_assert(sizeof(LeafRecord) == 80);

template <class T>
void append(std::string& out, const T& value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof value);
}

std::string encode(const ProxySet& set) {
  std::string out;
  for (uint32_t b = 0; b < set.brick_count(); ++b) {
    const BrickProxy::Impl& impl = set.brick(b).impl();
    const ProxyFrame& f = impl.frame;
    FrameRecord frame{};
    for (int a = 0; a < 3; ++a) {
      frame.origin[a] = f.origin_WS[a];
      frame.dims[a] = f.dims_IS[a];
    }
    frame.voxel_size = f.voxel_size_WS;
    frame.margin = f.margin_WS;
    append(out, frame);
    const ProxyRoot& root = *impl.root;
    const auto leaf_count = static_cast<uint32_t>(root.leafCount());
    append(out, leaf_count);
    append(out, uint32_t{0});
    std::vector<const ProxyLeaf*> leaves;
    for (auto inner = root.cbeginChildOn(); inner; ++inner) {
      for (auto leaf = inner->cbeginChildOn(); leaf; ++leaf) leaves.push_back(&*leaf);
    }
    for (const ProxyLeaf* leaf : leaves) {
      LeafRecord record{};
      const openvdb::Coord origin = leaf->origin();
      for (int a = 0; a < 3; ++a) record.origin[a] = origin[a];
      for (openvdb::Index offset = 0; offset < ProxyLeaf::SIZE; ++offset) {
        if (leaf->isValueOn(offset)) record.words[offset >> 6] |= uint64_t{1} << (offset & 63);
      }
      append(out, record);
    }
  }
  return out;
}

bool same_bits(double a, double b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

Expected<std::string> read_whole_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    if (errno == ENOENT) return not_found(path + " does not exist");
    return io_error_from_errno("cannot open " + path);
  }
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) return io_error_from_errno("cannot read " + path);
  return std::move(s).str();
}

// Header checks shared by both readers; `bytes` is the whole file.
Expected<ProxyFileHeader> check_header(const std::string& path, const std::string& bytes) {
  ProxyFileHeader header{};
  if (bytes.size() < sizeof header) {
    return data_loss(path + " is truncated (" + std::to_string(bytes.size()) + " bytes, header alone is " +
                     std::to_string(sizeof header) + ")");
  }
  std::memcpy(&header, bytes.data(), sizeof header);
  if (std::memcmp(header.magic, kProxyMagic, sizeof header.magic) != 0) {
    return data_loss(path + " is not an Outcore proxy file (bad magic)");
  }
  if (header.format_version != kProxyFormatVersion) {
    return failed_precondition(path + " has proxy format version " + std::to_string(header.format_version) +
                               "; this outcore uses version " + std::to_string(kProxyFormatVersion));
  }
  if (header.header_bytes != sizeof header) return data_loss(path + " has a malformed header");
  if (bytes.size() != sizeof header + header.payload_bytes) {
    return data_loss(path + " is " +
                     (bytes.size() < sizeof header + header.payload_bytes ? "truncated" : "too long") + " (" +
                     std::to_string(bytes.size()) + " bytes, expected " +
                     std::to_string(sizeof header + header.payload_bytes) + ")");
  }
  if (checksum64(bytes.data() + sizeof header, header.payload_bytes) != header.payload_checksum) {
    return data_loss(path + " is corrupted (checksum mismatch)");
  }
  return header;
}

}  // namespace

uint64_t store_fingerprint(const Manifest& manifest) {
  Checksum64 sum;
  const uint64_t count = manifest.bricks.size();
  sum.update(&count, sizeof count);
  for (const BrickRecord& b : manifest.bricks) {
    const float bounds[6] = {b.bounds.lo.x, b.bounds.lo.y, b.bounds.lo.z,
                             b.bounds.hi.x, b.bounds.hi.y, b.bounds.hi.z};
    sum.update(bounds, sizeof bounds);
    sum.update(&b.triangle_count, sizeof b.triangle_count);
    sum.update(&b.checksum, sizeof b.checksum);
  }
  return sum.digest();
}

Status write_proxy_file(const std::string& directory, const ProxySet& set, uint64_t fingerprint) {
  const std::string payload = encode(set);
  ProxyFileHeader header{};
  std::memcpy(header.magic, kProxyMagic, sizeof header.magic);
  header.format_version = kProxyFormatVersion;
  header.header_bytes = sizeof header;
  header.resolution = set.config().resolution;
  header.brick_count = set.brick_count();
  header.margin_voxels = kProxyMarginVoxels;
  header.store_fingerprint = fingerprint;
  header.active_voxels = set.active_voxels();
  header.memory_bytes = set.memory_bytes();
  header.payload_bytes = payload.size();
  header.payload_checksum = checksum64(payload.data(), payload.size());

  // Readable by all, as the store's other files (a server may run as another user).
  AtomicWriteOptions options;
  options.sync = true;
  options.mode = 0644;
  const std::string_view parts[] = {std::string_view(reinterpret_cast<const char*>(&header), sizeof header),
                                    payload};
  return write_file_atomically(directory + "/" + kProxyFileName, parts, options);
}

Expected<ProxyFileHeader> read_proxy_file_header(const std::string& path) {
  OUTCORE_ASSIGN_OR_RETURN(const std::string bytes, read_whole_file(path));
  return check_header(path, bytes);
}

Expected<std::unique_ptr<const ProxySet>> read_proxy_file(const std::string& path, const Manifest& manifest,
                                                          const ProxyBuildConfig& config) {
  OUTCORE_ASSIGN_OR_RETURN(const std::string bytes, read_whole_file(path));
  OUTCORE_ASSIGN_OR_RETURN(const ProxyFileHeader header, check_header(path, bytes));
  if (header.resolution != config.resolution) {
    return failed_precondition(path + " has resolution " + std::to_string(header.resolution) + ", wanted " +
                               std::to_string(config.resolution));
  }
  if (!same_bits(header.margin_voxels, kProxyMarginVoxels)) {
    return failed_precondition(path + " was built with another margin");
  }
  if (header.store_fingerprint != store_fingerprint(manifest) ||
      header.brick_count != manifest.bricks.size()) {
    return failed_precondition(path + " was built for another scene store");
  }

  const char* cursor = bytes.data() + sizeof header;
  const char* const end = bytes.data() + bytes.size();
  auto take = [&](void* out, std::size_t size) {
    if (static_cast<std::size_t>(end - cursor) < size) return false;
    std::memcpy(out, cursor, size);
    cursor += size;
    return true;
  };
  std::vector<BrickProxy> proxies;
  proxies.reserve(manifest.bricks.size());
  for (uint32_t b = 0; b < manifest.bricks.size(); ++b) {
    const std::string brick = "brick " + std::to_string(b);
    auto bad = [&](const std::string& what) { return data_loss(path + ": " + brick + ": " + what); };
    FrameRecord frame{};
    uint32_t counts[2] = {0, 0};
    if (!take(&frame, sizeof frame) || !take(counts, sizeof counts)) return bad("truncated");
    const ProxyFrame want = proxy_frame_for(manifest.bricks[b].bounds, manifest.bounds, config);
    bool frame_ok =
        same_bits(frame.voxel_size, want.voxel_size_WS) && same_bits(frame.margin, want.margin_WS);
    for (int a = 0; a < 3; ++a) {
      frame_ok =
          frame_ok && same_bits(frame.origin[a], want.origin_WS[a]) && frame.dims[a] == want.dims_IS[a];
    }
    if (!frame_ok) return bad("frame does not match the brick's bounds");
    auto impl = std::make_unique<BrickProxy::Impl>();
    impl->frame = want;
    impl->root = std::make_unique<ProxyRoot>(false);
    ProxyRoot& tree = *impl->root;
    for (uint32_t l = 0; l < counts[0]; ++l) {
      LeafRecord record{};
      if (!take(&record, sizeof record)) return bad("truncated");
      const openvdb::Coord origin(record.origin[0], record.origin[1], record.origin[2]);
      for (int a = 0; a < 3; ++a) {
        if (origin[a] % 8 != 0 || origin[a] < 0 || origin[a] >= want.dims_IS[a]) {
          return bad("leaf outside the domain");
        }
      }
      if (tree.probeConstLeaf(origin) != nullptr) return bad("repeated leaf");
      ProxyLeaf* leaf = tree.touchLeaf(origin);
      for (openvdb::Index offset = 0; offset < ProxyLeaf::SIZE; ++offset) {
        if ((record.words[offset >> 6] >> (offset & 63)) & 1) leaf->setValueOn(offset);
      }
    }
    impl->finish();
    proxies.emplace_back(std::move(impl));
  }
  if (cursor != end) return data_loss(path + " has trailing bytes");
  return std::unique_ptr<const ProxySet>(new ProxySet(config, std::move(proxies)));
}

}  // namespace outcore
