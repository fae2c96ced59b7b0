// The gRPC channel every client of ours opens (SceneClient, `outcore health`):
// plaintext, or TLS trusting a given CA (and presenting a client certificate
// when the server requires one), and a bearer token added to every call's
// metadata by a client interceptor, so that no call can forget it.
//
// Thread-safety: make_channel is a pure function; the channel is gRPC's
// (thread-safe).
#pragma once

#include <grpcpp/channel.h>
#include <grpcpp/support/channel_arguments.h>

#include <memory>
#include <string>

#include "core/util/status.h"

namespace outcore::client {

struct ChannelSecurity {
  // TLS when set: the CA (PEM file) that signed the server's certificate.
  std::string tls_ca_file;
  // For servers that require client certificates (serve --tls-client-ca).
  std::string tls_cert_file;
  std::string tls_key_file;
  // Sent as "authorization: Bearer <token>" on every call when not empty.
  std::string auth_token;
  bool tls() const { return !tls_ca_file.empty(); }
};

// A channel to `address`; IO_ERROR naming a PEM file that cannot be read,
// INVALID_ARGUMENT when a client certificate comes without TLS or its key.
Expected<std::shared_ptr<grpc::Channel>> make_channel(const std::string& address,
                                                      const ChannelSecurity& security,
                                                      const grpc::ChannelArguments& arguments);

}  // namespace outcore::client
