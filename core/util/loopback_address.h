// Network addresses: whether one names this host, for the same-host shared
// payloads (the server checks the peer gRPC reports, server/shared_payload.h,
// and the clients the target they were given, client/cpp/scene_client.h, with
// the same rules for the address itself), and the port of a HOST:PORT.
//
// Thread-safety: pure functions.
#pragma once

#include <cstdint>
#include <string_view>

#include "core/util/status.h"

namespace outcore {

// "[v6]:port" -> "v6", "host:port" -> "host"; anything else (a bare host, a
// bare IPv6 address) as it is. An unclosed '[' gives "".
std::string_view host_of(std::string_view host_port);

// True for a numeric loopback address: IPv4 127.0.0.0/8, IPv6 ::1, and
// IPv4-mapped ::ffff:127.x.y.z. Names (even "localhost"), scoped IPv6
// addresses and anything unparsable are false.
bool is_loopback_ip(std::string_view numeric_host);

// is_loopback_ip, or the name localhost (any case, with or without the
// root's trailing dot): a host that names this machine.
bool is_loopback_host(std::string_view host);

// The port of "host:port" or "[v6]:port". INVALID_ARGUMENT naming
// `host_port` when the host is empty or the port is missing, not a decimal
// number or outside [min_port, 65535]: the resolver would otherwise take a
// port modulo 65536 (99999 listens on 34463).
Expected<uint16_t> port_of(std::string_view host_port, uint16_t min_port);

}  // namespace outcore
