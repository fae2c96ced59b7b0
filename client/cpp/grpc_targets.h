// What a gRPC target string names, checked before a channel is made: whether
// it is on this host (the clients' shared-memory payloads need that) and
// whether its ports are real ones (gRPC's resolver would take a port modulo
// 65536 and connect elsewhere).
//
// Thread-safety: pure functions.
#pragma once

#include <string>

#include "core/util/status.h"

namespace outcore::client {

// True for gRPC targets on this host: 127.x.y.z, localhost, [::1], unix:.
bool is_loopback_target(const std::string& address);

// INVALID_ARGUMENT naming `address` when a HOST:PORT in it (bare, after
// dns:, or in an ipv4:/ipv6: list) has no port or one that is not 1 to 65535:
// gRPC's resolver would take the port modulo 65536 and connect elsewhere.
// Targets of other schemes (unix:, ...) are left to gRPC.
Status check_target_ports(const std::string& address);

}  // namespace outcore::client
