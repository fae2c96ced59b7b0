#include "core/store/store_commit.h"

#include <string>

#include "core/store/pack_output.h"
#include "core/store/store_format.h"
#include "core/upper/upper_hierarchy_builder.h"

namespace outcore::packing {

namespace {

Manifest make_manifest(const PackContext& context, const ScanResult& scan, std::vector<BrickRecord> bricks) {
  Manifest manifest;
  manifest.format_version = kStoreFormatVersion;
  manifest.outcore_version = OUTCORE_VERSION;
  manifest.brick_triangles_target = context.brick_triangles;
  manifest.bounds = scan.bounds;
  manifest.triangle_count = scan.triangles;
  manifest.degenerate_count = scan.degenerate;
  manifest.inputs = scan.inputs;
  manifest.bricks = std::move(bricks);
  std::vector<Aabb> brick_bounds;
  brick_bounds.reserve(manifest.bricks.size());
  for (const BrickRecord& b : manifest.bricks) brick_bounds.push_back(b.bounds);
  manifest.upper = build_upper_hierarchy(brick_bounds);
  return manifest;
}

}  // namespace

Expected<Manifest> commit_store(const PackContext& context, const ScanResult& scan,
                                std::vector<BrickRecord> bricks, AtomicDirectory& store,
                                const std::filesystem::path& output) {
  const PackOptions& options = context.options;
  Manifest manifest = make_manifest(context, scan, std::move(bricks));
  OUTCORE_RETURN_IF_ERROR(validate_manifest(manifest, options.output));
  const std::string manifest_path = store.path() + "/" + kManifestFileName;
  OUTCORE_RETURN_IF_ERROR(write_manifest(manifest_path, manifest));
  if (options.sync) OUTCORE_RETURN_IF_ERROR(sync_file(manifest_path));
  OUTCORE_RETURN_IF_ERROR(context.check_cancel());
  OUTCORE_RETURN_IF_ERROR(check_output(options, output));
  OUTCORE_RETURN_IF_ERROR(store.commit(options.sync, "store"));
  return manifest;
}

}  // namespace outcore::packing
