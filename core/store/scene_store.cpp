#include "core/store/scene_store.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <vector>

#include "core/store/store_format.h"
#include "core/util/checksum.h"

namespace outcore {

Expected<std::shared_ptr<const SceneStore>> SceneStore::open(const std::string& directory) {
  std::error_code ec;
  if (!std::filesystem::is_directory(directory, ec)) {
    return not_found("scene store " + directory + " does not exist or is not a directory");
  }
  std::shared_ptr<SceneStore> store(new SceneStore());
  store->directory_ = directory;
  const std::string manifest_path = directory + "/" + kManifestFileName;
  if (!std::filesystem::exists(manifest_path, ec)) {
    return not_found("scene store " + directory + " has no " + kManifestFileName +
                     " (not a scene store, or an interrupted pack)");
  }
  // Before the read: a manifest replaced in between then reads as changed.
  struct stat manifest_info {};
  if (::stat(manifest_path.c_str(), &manifest_info) != 0) {
    return io_error_from_errno("cannot stat " + manifest_path);
  }
  store->manifest_identity_ = identity_of(manifest_info);
  OUTCORE_ASSIGN_OR_RETURN(store->manifest_, read_manifest(manifest_path));

  const std::string data_path = directory + "/" + kBrickDataFileName;
  store->brick_fd_ = ::open(data_path.c_str(), O_RDONLY | O_CLOEXEC);
  if (store->brick_fd_ < 0) return io_error_from_errno("cannot open brick data " + data_path);
  struct stat st {};
  if (fstat(store->brick_fd_, &st) != 0) return io_error_from_errno("cannot stat " + data_path);
  store->brick_file_identity_ = identity_of(st);
  const auto data_bytes = static_cast<uint64_t>(st.st_size);
  const auto& bricks = store->manifest_.bricks;
  for (size_t id = 0; id < bricks.size(); ++id) {
    if (bricks[id].offset + bricks[id].size_bytes > data_bytes) {
      return data_loss("scene store " + directory + ": brick " + std::to_string(id) + " is truncated (" +
                       data_path + " has " + std::to_string(data_bytes) + " bytes, brick ends at " +
                       std::to_string(bricks[id].offset + bricks[id].size_bytes) + ")");
    }
  }
  store->bytes_on_disk_ = data_bytes + std::filesystem::file_size(manifest_path, ec);
  return std::shared_ptr<const SceneStore>(std::move(store));
}

Status SceneStore::check_unchanged_on_disk() const {
  for (const auto& [name, identity] : {std::pair{kManifestFileName, &manifest_identity_},
                                       std::pair{kBrickDataFileName, &brick_file_identity_}}) {
    const std::string path = directory_ + "/" + name;
    struct stat info {};
    if (::stat(path.c_str(), &info) != 0) {
      if (errno == ENOENT || errno == ENOTDIR) {
        return failed_precondition("the scene store " + directory_ + " was removed from disk (" + path +
                                   " is gone) since it was opened");
      }
      return io_error_from_errno("cannot stat " + path);
    }
    if (identity_of(info) != *identity) {
      return failed_precondition("the scene store " + directory_ +
                                 " was replaced on disk (by pack --force?) since it was opened: " + path +
                                 " is another file now");
    }
  }
  return Status::Ok();
}

SceneStore::~SceneStore() {
  if (brick_fd_ >= 0) ::close(brick_fd_);
}

namespace {
Status pread_fully(int fd, void* buffer, uint64_t bytes, uint64_t offset) {
  auto* out = static_cast<char*>(buffer);
  while (bytes > 0) {
    const ssize_t got = ::pread(fd, out, bytes, static_cast<off_t>(offset));
    if (got < 0) {
      if (errno == EINTR) continue;
      return io_error_from_errno("read failed");
    }
    if (got == 0) return data_loss("unexpected end of file");
    out += got;
    bytes -= static_cast<uint64_t>(got);
    offset += static_cast<uint64_t>(got);
  }
  return Status::Ok();
}
}  // namespace

Status SceneStore::load_brick(uint32_t brick_id, BrickData& out) const {
  if (brick_id >= manifest_.bricks.size()) {
    return out_of_range("brick " + std::to_string(brick_id) + " does not exist (the scene has " +
                        std::to_string(manifest_.bricks.size()) + " bricks)");
  }
  const BrickRecord& record = manifest_.bricks[brick_id];
  const std::string name = "scene store " + directory_ + ": brick " + std::to_string(brick_id);
  const uint64_t count = record.triangle_count;
  BrickHeader header{};
  out.brick_id = brick_id;
  out.triangles.resize(count);
  out.ids.resize(count);
  Status status = pread_fully(brick_fd_, &header, sizeof header, record.offset);
  if (status.ok())
    status =
        pread_fully(brick_fd_, out.triangles.data(), count * sizeof(Triangle), record.offset + sizeof header);
  if (status.ok()) {
    status = pread_fully(brick_fd_, out.ids.data(), count * sizeof(TriangleId),
                         record.offset + sizeof header + count * sizeof(Triangle));
  }
  if (!status.ok()) return status.with_context(name);
  if (std::memcmp(header.magic, kBrickMagic, sizeof header.magic) != 0 || header.brick_id != brick_id ||
      header.triangle_count != count || header.payload_bytes != brick_payload_bytes(count)) {
    return data_loss(name + " has a corrupted header");
  }
  Checksum64 checksum;
  checksum.update(&header, sizeof header);
  checksum.update(out.triangles.data(), count * sizeof(Triangle));
  checksum.update(out.ids.data(), count * sizeof(TriangleId));
  if (checksum.digest() != record.checksum) return data_loss(name + " is corrupted (checksum mismatch)");
  return Status::Ok();
}

}  // namespace outcore
