// A SceneClient over replicas (issue 30, docs/SCALING.md). Routing by brick
// (the default): the scene's bricks are shared out on the ring
// (replica_ring.h), every replica traces the whole batch in its own bricks
// (CallOptions::only_bricks) and the nearest answer is kept (the engine's
// tie rule; occlusion ORed), so each brick is built on one replica. Routing
// by ray: each batch split by routing key, the parts sent to their replicas
// in parallel, the answers put back in input order. A part whose replica is
// unreachable (UNAVAILABLE, reported as IO_ERROR) goes to the next replica on
// the ring, and that replica is left out of later batches. Any replica
// answers any ray the same: routing changes cache hits and speed, never an
// answer. `outcore query --server a,b,c` uses it. Over a dns: target
// (connect_dns) the name is resolved again before a batch once `refresh` has
// passed: replicas that appeared join the ring, those gone leave it (a
// headless Service scaled up or down), as the Python client does.
//
// Thread-safety: intersect/occluded may be called from several threads (the
// replicas' clients are thread-safe; each batch routes over one snapshot of
// the replicas; the snapshot and the set of down replicas are locked).
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "client/cpp/scene_client.h"

namespace outcore::client {

enum class ReplicaRouting { kBricks, kRays };

class ReplicaRouter {
 public:
  // Connects to the replicas; those that cannot be reached (UNAVAILABLE)
  // are left out, other errors (TLS files, a bad address) are returned, as
  // is the first error when none can be reached.
  static Expected<std::unique_ptr<ReplicaRouter>> connect(const std::vector<std::string>& addresses,
                                                          const ConnectOptions& options = {});
  // The replicas a "dns:///NAME:PORT" target resolves to, resolved again
  // before a batch when `refresh` has passed since the last resolution (a
  // failed resolution keeps the replicas known). Errors as connect() and
  // replica_list().
  using Resolver = std::function<Expected<std::vector<std::string>>()>;
  static constexpr std::chrono::milliseconds kResolveEvery{30000};
  static Expected<std::unique_ptr<ReplicaRouter>> connect_dns(
      const std::string& target, const ConnectOptions& options = {},
      std::chrono::milliseconds refresh = kResolveEvery);
  // connect_dns over any resolver (tests: a list that changes).
  static Expected<std::unique_ptr<ReplicaRouter>> connect_resolved(Resolver resolver,
                                                                   const ConnectOptions& options,
                                                                   std::chrono::milliseconds refresh);

  Status intersect(std::span<const Ray> rays, std::span<Hit> hits, const CallOptions& options = {},
                   CallStats* stats = nullptr);
  Status occluded(std::span<const Ray> rays, std::span<uint8_t> occluded, const CallOptions& options = {},
                  CallStats* stats = nullptr);

  // Before the first batch (not thread-safe against running batches).
  void set_routing(ReplicaRouting routing) { routing_ = routing; }
  ReplicaRouting routing() const { return routing_; }

  // Parts the last batches sent again to another replica.
  uint64_t failovers() const;
  // Routing by brick: each live replica's bricks (by sorted address; empty
  // for a replica down).
  std::vector<std::vector<uint32_t>> plan_bricks() const;
  // How many rays of each replica (by sorted address) the batch would send.
  std::vector<uint64_t> plan_loads(std::span<const Ray> rays) const;
  std::vector<std::string> replicas() const;

 private:
  // The replicas a batch routes over: sorted addresses and their clients.
  struct Members {
    std::vector<std::string> replicas;
    std::vector<std::shared_ptr<SceneClient>> clients;
  };

  ReplicaRouter() = default;
  // Members for `addresses`, reusing the clients of `known` (may be null)
  // and connecting the others; unreachable ones left out (see connect()).
  Expected<std::shared_ptr<const Members>> join(const std::vector<std::string>& addresses,
                                                const Members* known) const;
  std::shared_ptr<const Members> members() const;
  // Resolves again when due (connect_dns); keeps the members on failure.
  void refresh_members();
  template <class Answer>
  Status run(std::span<const Ray> rays, std::span<Answer> out, const CallOptions& options, CallStats* stats);
  template <class Answer>
  Status run_by_bricks(const Members& members, std::span<const Ray> rays, std::span<Answer> out,
                       const CallOptions& options, CallStats* stats);
  // Calls `replica` (updated) and, while it is unreachable, the next ones up
  // on the ring, each marked down.
  template <class Answer>
  Status call_with_failover(const Members& members, uint32_t& replica, std::span<const Ray> rays,
                            std::span<Answer> out, const CallOptions& options, CallStats& stats);
  // The replicas up: indices into members.replicas, and into `names` their
  // addresses (sorted, as members.replicas).
  std::vector<uint32_t> live(const Members& members, std::vector<std::string>& names) const;
  // Each ray's replica (index into members.replicas) among those up.
  std::vector<uint32_t> route(const Members& members, std::span<const Ray> rays) const;
  // Each live replica's bricks (by index into members.replicas).
  std::vector<std::vector<uint32_t>> share_bricks(const Members& members) const;

  struct BrickPlace {
    uint64_t position;  // brick_ring_position
    uint64_t triangles;
  };

  ConnectOptions options_;
  ReplicaRouting routing_ = ReplicaRouting::kBricks;
  Vec3f lo_, hi_;
  std::vector<BrickPlace> bricks_;  // by brick id (SceneInfo.bricks)
  Resolver resolver_;               // empty for a fixed list
  std::chrono::milliseconds refresh_{kResolveEvery};
  std::mutex refresh_mutex_;  // one resolution at a time
  std::chrono::steady_clock::time_point next_refresh_;
  mutable std::mutex mutex_;
  std::shared_ptr<const Members> members_;
  std::set<std::string> down_;  // by address
  uint64_t failovers_ = 0;
};

// The replica list of a --server value "a:1,b:2,c:3" (no scheme prefix;
// "ipv4:..." lists are one gRPC target), or the addresses a "dns:///NAME:PORT"
// target resolves to now (getaddrinfo; a headless Service's pods); empty
// when it names one server. IO_ERROR naming a dns: target that resolves to
// nothing.
Expected<std::vector<std::string>> replica_list(const std::string& server);

}  // namespace outcore::client
