#include "core/store/pack_output.h"

#include <spdlog/spdlog.h>

#include <cstring>
#include <fstream>

#include "core/store/manifest.h"
#include "core/store/store_format.h"
#include "core/util/temporary_directory.h"

namespace outcore::packing {

namespace fs = std::filesystem;

namespace {

// --force: whether the existing `output` may be replaced (an Outcore store
// holding no input of this pack); an error naming what it is otherwise.
Status check_replaceable(const PackOptions& options, const fs::path& output) {
  std::error_code ec;
  // An input inside the target (or the target itself) would be deleted with it.
  for (const std::string& input : options.inputs) {
    if (input.starts_with("gen:")) continue;
    const fs::path real = fs::canonical(input, ec);
    if (ec) continue;  // a missing input fails when it is opened
    for (fs::path p = real;; p = p.parent_path()) {
      if (fs::equivalent(p, output, ec)) {
        return invalid_argument("refusing to replace " + output.string() + " (--force): input '" + input +
                                "' of this pack " + (p == real ? "is that path" : "lies inside it"));
      }
      if (p == p.parent_path()) break;
    }
  }
  const std::string refusal = "refusing to replace " + output.string() + " (--force replaces only a store): ";
  const fs::file_status status = fs::symlink_status(output, ec);
  if (fs::is_symlink(status))
    return failed_precondition(refusal + "it is a symbolic link; give the store's own path");
  if (!fs::is_directory(status)) {
    return failed_precondition(
        refusal + (fs::is_regular_file(status) ? "it is a regular file" : "it is not a directory") +
        ", not an Outcore store");
  }
  // A store is what this packer writes: the manifest with the store's magic
  // (of any format version, or damaged: repacking is how such a store is
  // mended) and nothing but store files, so that nothing else can be lost.
  const std::string manifest = (output / kManifestFileName).string();
  char magic[sizeof kManifestMagic] = {};
  {
    std::ifstream in(manifest, std::ios::binary);
    in.read(magic, sizeof magic);
    if (!in || std::memcmp(magic, kManifestMagic, sizeof magic) != 0)
      return failed_precondition(refusal + "it is not an Outcore store (no " +
                                 std::string(kManifestFileName) + " with the store's magic)");
  }
  for (fs::directory_iterator it(output, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const bool store_file = name == kManifestFileName || name == kBrickDataFileName ||
                            name == kProxyFileName ||
                            name.starts_with("." + std::string(kProxyFileName) + ".tmp-") ||
                            name.starts_with(std::string(kProxyFileName) + ".partial-");
    if (!store_file)
      return failed_precondition(refusal + "it holds '" + name + "', which is not part of an Outcore store");
  }
  if (ec) return io_error("cannot list " + output.string() + ": " + ec.message());
  return Status::Ok();
}

}  // namespace

fs::path normalized_output(const std::string& output) {
  std::error_code ec;
  fs::path path = fs::absolute(output, ec).lexically_normal();
  if (!path.has_filename()) path = path.parent_path();
  return path;
}

Status validate_pack_options(const PackOptions& options) {
  if (options.inputs.empty()) return invalid_argument("no inputs given");
  if (options.output.empty()) return invalid_argument("no output store given (-o)");
  if (options.brick_triangles.has_value() &&
      (*options.brick_triangles == 0 || *options.brick_triangles > kMaxBrickTriangles)) {
    return invalid_argument("--brick-tris must be between 1 and " + std::to_string(kMaxBrickTriangles) +
                            ", got " + std::to_string(*options.brick_triangles));
  }
  if (options.memory_mb < kMinPackMemoryMb) {
    return invalid_argument("--mem-mb must be at least " + std::to_string(kMinPackMemoryMb) + ", got " +
                            std::to_string(options.memory_mb));
  }
  if (options.vertex_memory_mb > options.memory_mb / 2) {
    return invalid_argument("--vertex-mem-mb must be at most half of --mem-mb (" +
                            std::to_string(options.memory_mb / 2) + "), got " +
                            std::to_string(options.vertex_memory_mb));
  }
  if (options.inputs.size() >= 0xffffffffull) return invalid_argument("too many inputs");
  return check_output(options, normalized_output(options.output));
}

Status check_output(const PackOptions& options, const fs::path& output) {
  std::error_code ec;
  // symlink_status: a dangling link at -o is something there too.
  if (!fs::exists(fs::symlink_status(output, ec))) return Status::Ok();
  if (!options.overwrite) {
    return already_exists("output " + options.output + " already exists (use --force to replace it)");
  }
  return check_replaceable(options, output);
}

void remove_stale_partials(const fs::path& output) {
  // A pack that died (SIGKILL, power loss) could not remove its temporary
  // directory; left alone, these pile up and fill the disk.
  for (const StalePartial& stale : find_stale_partials(output.string())) {
    std::error_code ec;
    fs::remove_all(stale.path, ec);
    if (ec) {
      spdlog::warn("cannot remove {}, left by pack process {} (no longer running): {}", stale.path, stale.pid,
                   ec.message());
    } else {
      spdlog::warn("removed {}, left by pack process {} (no longer running)", stale.path, stale.pid);
    }
  }
}

}  // namespace outcore::packing
