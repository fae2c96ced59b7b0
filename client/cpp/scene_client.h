// SceneClient: the C++ client of outcore.v1.SceneQuery (see
// docs/REMOTE_API.md). Rays and hits are the engine's own Ray and Hit (the
// wire's F32X8 and hit layouts), so batches are copied once into a request
// and once out of each reply. A batch too large for one message (the server's
// max message size, learnt from GetSceneInfo at connect) is sent as a stream of
// chunks, written by a second thread while replies are read, so the server
// traces one chunk while the next is on the wire; answers keep their order.
//
// Errors come back as outcore::Status with the gRPC code's name leading the
// message ("DEADLINE_EXCEEDED: ..."), converted in one place.
//
// Thread-safety: one SceneClient may be used from several threads at once
// (gRPC channels and stubs are thread-safe; calls share no state).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "core/query/query_engine.h"
#include "core/query/ray_types.h"
#include "core/util/status.h"
#include "outcore/v1/scene_query.grpc.pb.h"

namespace outcore::client {

struct ConnectOptions {
  // How long connect() waits for the server to answer GetSceneInfo.
  double timeout_seconds = 10.0;
};

struct CallOptions {
  // Deadline of the whole batch (all chunks), seconds; 0 means none.
  double deadline_seconds = 0;
  // Invalid rays are INVALID_ARGUMENT naming the first one, instead of misses.
  bool strict = false;
  // Ask the server to trace rays in input order (answers are identical).
  bool no_reorder = false;
  // Rays per message; 0 picks the most the server's max message size allows,
  // except that batches of more than 262,144 rays are streamed in chunks of
  // at most 65,536 (the wire then overlaps tracing). Batches up to one
  // message go unary, larger ones are streamed.
  uint64_t chunk_rays = 0;
};

// Sums of the per-message engine figures of one call.
struct CallStats {
  uint64_t messages = 0;  // replies received (1 for a unary call)
  v1::QueryStats engine;  // summed over replies
};

class SceneClient {
 public:
  // Connects to HOST:PORT and fetches the scene info (checking the server is
  // up and learning its max message size).
  static Expected<std::unique_ptr<SceneClient>> connect(const std::string& address,
                                                        const ConnectOptions& options = {});

  // Closest hits; hits.size() must equal rays.size().
  Status intersect(std::span<const Ray> rays, std::span<Hit> hits, const CallOptions& options = {},
                   CallStats* stats = nullptr);
  // occluded[i] = 1 when ray i hits anything in [tnear, tfar], else 0.
  Status occluded(std::span<const Ray> rays, std::span<uint8_t> occluded, const CallOptions& options = {},
                  CallStats* stats = nullptr);

  Expected<v1::SceneInfo> scene_info(double deadline_seconds = 0);
  Expected<v1::ServerStats> stats(double deadline_seconds = 0);

  // The most rays one message holds (the chunk size for CallOptions::chunk_rays
  // 0, capped at 65,536 for batches of more than 262,144 rays).
  uint64_t max_chunk_rays() const { return max_chunk_rays_; }
  const v1::SceneInfo& connected_scene() const { return scene_; }

 private:
  SceneClient(std::shared_ptr<grpc::Channel> channel, std::string address);
  template <class Response>
  Status run(std::span<const Ray> rays, std::span<uint8_t> out, uint32_t out_bytes_per_ray,
             const CallOptions& options, CallStats* stats);

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::SceneQuery::Stub> stub_;
  std::string address_;
  v1::SceneInfo scene_;
  uint64_t max_chunk_rays_ = 0;
};

// The engine's figures from the wire's (a reply's, or CallStats::engine).
// Those the wire does not carry per request stay 0: peak_bytes_resident,
// cache_budget_bytes and proxy_bytes (ServerStats has them).
QueryStats to_query_stats(const v1::QueryStats& wire);

// The one conversion of a gRPC status into the client's Status.
Status from_grpc_status(const grpc::Status& status, const std::string& context);

}  // namespace outcore::client
