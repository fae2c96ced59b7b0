// A SceneClient over replicas (issue 30, docs/SCALING.md): each batch split
// by routing key (replica_ring.h), the parts sent to their replicas in
// parallel, the answers put back in input order; a part whose replica is
// unreachable (UNAVAILABLE, reported as IO_ERROR) goes to the next replica on
// the ring, and that replica is left out of later batches. Any replica
// answers any ray the same: routing changes cache hits and speed, never an
// answer. `outcore query --server a,b,c` uses it.
//
// Thread-safety: intersect/occluded may be called from several threads (the
// replicas' clients are thread-safe; the set of down replicas is locked).
#pragma once

#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "client/cpp/scene_client.h"

namespace outcore::client {

class ReplicaRouter {
 public:
  // Connects to the replicas; those that cannot be reached (UNAVAILABLE)
  // are left out, other errors (TLS files, a bad address) are returned, as
  // is the first error when none can be reached.
  static Expected<std::unique_ptr<ReplicaRouter>> connect(const std::vector<std::string>& addresses,
                                                          const ConnectOptions& options = {});

  Status intersect(std::span<const Ray> rays, std::span<Hit> hits, const CallOptions& options = {},
                   CallStats* stats = nullptr);
  Status occluded(std::span<const Ray> rays, std::span<uint8_t> occluded, const CallOptions& options = {},
                  CallStats* stats = nullptr);

  // Parts the last batches sent again to another replica.
  uint64_t failovers() const;
  // How many rays of each replica (by sorted address) the batch would send.
  std::vector<uint64_t> plan_loads(std::span<const Ray> rays) const;
  std::vector<std::string> replicas() const;

 private:
  ReplicaRouter() = default;
  template <class Answer>
  Status run(std::span<const Ray> rays, std::span<Answer> out, const CallOptions& options, CallStats* stats);
  // Each ray's replica (index into replicas_) among those up.
  std::vector<uint32_t> route(std::span<const Ray> rays) const;

  std::vector<std::string> replicas_;  // sorted
  std::vector<std::unique_ptr<SceneClient>> clients_;
  Vec3f lo_, hi_;
  mutable std::mutex mutex_;
  std::set<uint32_t> down_;
  uint64_t failovers_ = 0;
};

// The replica list of a --server value "a:1,b:2,c:3" (no scheme prefix;
// "ipv4:..." lists are one gRPC target), or the addresses a "dns:///NAME:PORT"
// target resolves to now (getaddrinfo; a headless Service's pods); empty
// when it names one server. IO_ERROR naming a dns: target that resolves to
// nothing.
Expected<std::vector<std::string>> replica_list(const std::string& server);

}  // namespace outcore::client
