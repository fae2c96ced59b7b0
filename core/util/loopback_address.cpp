#include "core/util/loopback_address.h"

#include <arpa/inet.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <string>

namespace outcore {

std::string_view host_of(std::string_view host_port) {
  if (host_port.starts_with("[")) {
    const auto end = host_port.find(']');
    return end == std::string_view::npos ? std::string_view() : host_port.substr(1, end - 1);
  }
  if (std::count(host_port.begin(), host_port.end(), ':') == 1)
    return host_port.substr(0, host_port.find(':'));
  return host_port;
}

bool is_loopback_ip(std::string_view numeric_host) {
  // A scope ("fe80::1%eth0") is never loopback.
  if (numeric_host.find('%') != std::string_view::npos) return false;
  const std::string host(numeric_host);
  in_addr address4{};
  if (inet_pton(AF_INET, host.c_str(), &address4) == 1) return (ntohl(address4.s_addr) >> 24) == 127;
  in6_addr address6{};
  if (inet_pton(AF_INET6, host.c_str(), &address6) != 1) return false;
  if (IN6_IS_ADDR_LOOPBACK(&address6)) return true;
  return IN6_IS_ADDR_V4MAPPED(&address6) && address6.s6_addr[12] == 127;
}

Expected<uint16_t> port_of(std::string_view host_port, uint16_t min_port) {
  const std::string quoted = "'" + std::string(host_port) + "'";
  const std::size_t colon = host_port.rfind(':');
  const bool bracketed = host_port.starts_with("[");
  const std::size_t close = host_port.find(']');
  if (colon == std::string_view::npos ||
      (bracketed && (close == std::string_view::npos || colon != close + 1)) ||
      (!bracketed && std::count(host_port.begin(), host_port.end(), ':') != 1)) {
    return invalid_argument(quoted + " is not HOST:PORT (an IPv6 host in brackets: [::1]:PORT)");
  }
  if (host_of(host_port).empty()) return invalid_argument(quoted + " has no host (HOST:PORT)");
  const std::string_view port = host_port.substr(colon + 1);
  const std::string range = std::to_string(min_port) + " to 65535";
  if (port.empty()) return invalid_argument(quoted + " has no port (HOST:PORT, PORT " + range + ")");
  uint32_t value = 0;
  for (const char c : port) {
    if (c < '0' || c > '9') {
      return invalid_argument(quoted + ": the port '" + std::string(port) + "' is not a number " + range);
    }
    value = std::min<uint32_t>(value * 10 + static_cast<uint32_t>(c - '0'), 1u << 20);
  }
  if (value < min_port || value > 65535) {
    return invalid_argument(quoted + ": the port " + std::string(port) + " is outside " + range);
  }
  return static_cast<uint16_t>(value);
}

bool is_loopback_host(std::string_view host) {
  std::string lower(host);
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
  if (lower.ends_with(".")) lower.pop_back();
  return lower == "localhost" || is_loopback_ip(lower);
}

}  // namespace outcore
