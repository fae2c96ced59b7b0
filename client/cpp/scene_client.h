// SceneClient: the C++ client of outcore.v1.SceneQuery (see
// docs/REMOTE_API.md). Rays and hits are the engine's own Ray and Hit (the
// wire's F32X8 and hit layouts), so batches are copied once into a request
// and once out of each reply. A batch too large for one message (the server's
// max message size, learnt from GetSceneInfo at connect) is sent as a stream of
// chunks, written by a second thread while replies are read, so the server
// traces one chunk while the next is on the wire; answers keep their order.
//
// Same host: when the address is a loopback one (127.x, localhost, [::1],
// unix:) and the server accepts shared payloads (SceneInfo), a batch of at
// least kSharedMinRays rays with CallOptions::chunk_rays 0 goes as one unary
// call whose rays and answers sit in a shared-memory object this client owns
// (core/util/shared_memory.h, proto SharedPayload): one copy in, one copy
// out, nothing through gRPC or the socket. Objects are pooled and reused
// across calls (one per concurrent call) and unlinked with the client. If the
// server refuses (FAILED_PRECONDITION with its "refused" marker: it cannot
// open the object, another host's /dev/shm, --no-shared-payloads) the client
// stops using shared memory and sends that batch and later ones over gRPC;
// if no object can be made (a full /dev/shm), that batch and larger ones go
// over gRPC. Each object's header holds a random token sent with the call,
// so that only this client can name its objects.
//
// Errors come back as outcore::Status with the gRPC code's name leading the
// message ("DEADLINE_EXCEEDED: ..."), converted in one place.
//
// Thread-safety: one SceneClient may be used from several threads at once
// (gRPC channels and stubs are thread-safe; calls share no state).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "client/cpp/grpc_targets.h"
#include "client/cpp/secure_channel.h"
#include "core/query/query_engine.h"
#include "core/ray/ray_types.h"
#include "core/util/progress.h"
#include "core/util/shared_memory.h"
#include "core/util/status.h"
#include "outcore/v1/scene_query.grpc.pb.h"

namespace outcore::client {

struct ConnectOptions {
  // How long connect() waits for the server to answer GetSceneInfo.
  double timeout_seconds = 10.0;
  // Send large batches through shared memory when the server is on this
  // host (see SceneClient); false: always over gRPC.
  bool shared_memory = true;
  // TLS and the bearer token (secure_channel.h); plaintext without a token by default.
  ChannelSecurity security;
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
  // intersect(): the hit fields replies carry over the bytes path (fewer
  // bytes a ray: 4 for t, 12 for t and ids, 32 for all); fields not asked
  // for are a miss's defaults in `hits` (ids kInvalidId, u = v = 0, zero
  // normal), so with HIT_FIELDS_T test hits by a finite t. Shared-memory
  // calls always answer whole records.
  v1::HitFields hit_fields = v1::HIT_FIELDS_ALL;
  // Trace only these bricks (QueryRequest.only_bricks: a replica's part of
  // the scene); empty: every brick.
  std::vector<uint32_t> only_bricks;
  // Advanced by the rays of each reply as it arrives (a stream's chunk by
  // chunk; a unary or shared-memory call at its end); null: none.
  ProgressBar* progress = nullptr;
};

// Sums of the per-message engine figures of one call.
struct CallStats {
  uint64_t messages = 0;  // replies received (1 for a unary call)
  v1::QueryStats engine;  // summed over replies
  bool shared = false;    // the rays and answers went through shared memory
};

// Batches of at least this many rays use shared memory (when it is on):
// below it the bytes path costs less than mapping an object on the server.
inline constexpr uint64_t kSharedMinRays = 16384;

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

  // Every hit of each ray (CountIntersections / ListIntersections, in
  // chunks of max_chunk_rays(); a list's chunk is cut smaller when its hits
  // would not fit a message): counts[i] hits on ray i, and with `hits` every
  // hit, ray by ray, each ray's by t then ids. counts.size() must equal
  // rays.size(). Counts of a large batch go through shared memory as
  // intersect()'s do when the server takes them; lists always as bytes.
  Status count_intersections(std::span<const Ray> rays, std::span<uint32_t> counts,
                             const CallOptions& options = {}, CallStats* stats = nullptr);
  Status list_intersections(std::span<const Ray> rays, std::span<uint32_t> counts, std::vector<Hit>& hits,
                            const CallOptions& options = {}, CallStats* stats = nullptr);
  // Point queries (QueryPoints): `answers` gets the proto's bytes for `kind`
  // (44, 4, 4 or 1 per point), in chunks of what a message holds.
  Status query_points(std::span<const Vec3f> points, v1::PointQueryKind kind, std::string& answers,
                      const CallOptions& options = {}, CallStats* stats = nullptr);

  Expected<v1::SceneInfo> scene_info(double deadline_seconds = 0);
  Expected<v1::ServerStats> stats(double deadline_seconds = 0);

  // The most rays one message holds (the chunk size for CallOptions::chunk_rays
  // 0, capped at 65,536 for batches of more than 262,144 rays).
  uint64_t max_chunk_rays() const { return max_chunk_rays_; }
  const v1::SceneInfo& connected_scene() const { return scene_; }

 private:
  SceneClient(std::shared_ptr<grpc::Channel> channel, std::string address);
  // One chunk of an every-hit call: appends its counts and hits.
  Status every_hit_chunk(std::span<const Ray> rays, bool listing, std::vector<uint32_t>& counts,
                         std::vector<Hit>* hits, const CallOptions& options, CallStats* stats);
  template <class Response>
  Status run(std::span<const Ray> rays, std::span<uint8_t> out, uint32_t out_bytes_per_ray,
             const CallOptions& options, CallStats* stats);
  // The shared-memory call. Sets *send_bytes (and returns OK, answering
  // nothing) when the batch must go as bytes instead: the server refused
  // shared payloads (then for good), or no object of its size can be made.
  template <class Response>
  Status run_shared(std::span<const Ray> rays, std::span<uint8_t> out, uint32_t out_bytes_per_ray,
                    const CallOptions& options, CallStats* stats, bool* send_bytes);
  // The server's FAILED_PRECONDITION carried its "refused" marker.
  static bool shared_refused(const grpc::ClientContext& context);
  void stop_using_shared();
  // A pooled object of at least `bytes`, or an error when none can be made.
  Expected<std::unique_ptr<SharedMemoryObject>> take_object(uint64_t bytes);
  void give_back_object(std::unique_ptr<SharedMemoryObject> object);

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::SceneQuery::Stub> stub_;
  std::string address_;
  v1::SceneInfo scene_;
  uint64_t max_chunk_rays_ = 0;
  std::atomic<bool> use_shared_{false};
  // Objects of this many bytes or more could not be made: such batches go as bytes.
  std::atomic<uint64_t> shared_failed_bytes_{~uint64_t{0}};
  std::mutex objects_mutex_;
  std::vector<std::unique_ptr<SharedMemoryObject>> spare_objects_;  // at most kSpareObjects
};

// The engine's figures from the wire's (a reply's, or CallStats::engine).
// Those the wire does not carry per request stay 0: peak_bytes_resident,
// cache_budget_bytes and proxy_bytes (ServerStats has them).
QueryStats to_query_stats(const v1::QueryStats& wire);

// The one conversion of a gRPC status into the client's Status.
Status from_grpc_status(const grpc::Status& status, const std::string& context);

}  // namespace outcore::client
