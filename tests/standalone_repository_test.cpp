// The repository stands alone: nothing in it (code, tests, scripts, benches,
// docs, README examples) reads the development machine's shared folder beside
// the checkout, and the test models it needs are its own. CI also runs the
// whole suite in a copy with nothing beside it (.ci/run); this static check
// catches a new reference on any developer's machine first.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "tests/support/test_paths.h"

namespace outcore {
namespace OUTCORE_UNITY_ID {

namespace fs = std::filesystem;

bool is_scanned_text(const fs::path& path) {
  static const std::vector<std::string> kExtensions = {".cpp", ".h",    ".py",  ".sh",    ".md",
                                                       ".txt", ".toml", ".cfg", ".proto", ".yaml"};
  const std::string name = path.filename().string();
  if (name == "CMakeLists.txt" || name == "Dockerfile" || name == "run") return true;
  for (const std::string& ext : kExtensions)
    if (path.extension() == ext) return true;
  return false;
}

TEST(StandaloneRepository, NothingReadsTheSharedFolderBesideTheCheckout) {
  // Spelled in two parts so that this file does not match itself.
  const std::string sibling = std::string("../") + "shared";
  const fs::path root = OUTCORE_SOURCE_DIR;
  std::vector<std::string> offenders;
  std::size_t scanned = 0;
  for (const char* top : {"core", "server", "client", "proto", "tests", "scripts", "bench", "docs", "docker",
                          ".ci", "README.md", "CMakeLists.txt"}) {
    const fs::path start = root / top;
    if (!fs::exists(start)) continue;
    std::vector<fs::path> files;
    if (fs::is_regular_file(start)) {
      files.push_back(start);
    } else {
      for (auto it = fs::recursive_directory_iterator(start); it != fs::recursive_directory_iterator();
           ++it) {
        const std::string name = it->path().filename().string();
        // Generated or installed trees that are not part of the repository.
        if (it->is_directory() && (name == "__pycache__" || name == "build" || name.ends_with(".egg-info"))) {
          it.disable_recursion_pending();
          continue;
        }
        if (it->is_regular_file() && is_scanned_text(it->path())) files.push_back(it->path());
      }
    }
    for (const fs::path& file : files) {
      ++scanned;
      if (testing::contains(testing::read_file_bytes(file.string()), sibling))
        offenders.push_back(fs::relative(file, root).string());
    }
  }
  EXPECT_GT(scanned, 100u);
  EXPECT_TRUE(offenders.empty()) << "these read " << sibling << ": " << ::testing::PrintToString(offenders);
}

TEST(StandaloneRepository, CarriesItsTestModelsWithTheirAttribution) {
  for (const char* model : {"stanford-bunny.obj", "beast.obj", "fandisk.obj", "homer.obj", "spot.obj",
                            "teapot.obj", "igea.ply"}) {
    const std::string path = testing::model_path(model);
    EXPECT_TRUE(fs::is_regular_file(path)) << path;
    EXPECT_TRUE(testing::contains(testing::read_file_bytes(testing::model_path("README.md")), model))
        << model;
  }
  EXPECT_TRUE(fs::is_regular_file(fs::path(OUTCORE_SOURCE_DIR) / "LICENSE"));
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
