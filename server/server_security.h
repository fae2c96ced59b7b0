// How `outcore serve` is reached safely: TLS from PEM files (optionally
// requiring client certificates), the bearer token every SceneQuery call must
// carry, and the rule that a non-loopback address is never served in
// plaintext by accident.
//
// The token is checked by the service's handlers (SceneQueryService::
// authorize): gRPC C++ server interceptors cannot refuse a call, and its
// AuthMetadataProcessor works only with TLS credentials while a token is
// also useful on loopback. The health service (grpc.health.v1) and server
// reflection need no token, so probes and grpcurl's listing work without it.
//
// Thread-safety: pure functions.
#pragma once

#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_context.h>

#include <memory>
#include <string>

#include "core/util/status.h"

namespace outcore::server {

struct TlsFiles {
  std::string cert;       // --tls-cert: the server's certificate chain (PEM)
  std::string key;        // --tls-key: its private key (PEM)
  std::string client_ca;  // --tls-client-ca: when set, clients must present a certificate it signed
  bool enabled() const { return !cert.empty() || !key.empty(); }
};

// The metadata key a token travels in, and the scheme before it.
inline constexpr const char* kAuthorizationKey = "authorization";
inline constexpr const char* kBearerPrefix = "Bearer ";

// Insecure credentials without TLS; else TLS from the files. INVALID_ARGUMENT
// naming the flag when only one of cert and key is given, or a client CA
// without them; IO_ERROR naming the file that cannot be read.
Expected<std::shared_ptr<grpc::ServerCredentials>> server_credentials(const TlsFiles& tls);

// INVALID_ARGUMENT naming --tls-cert and --insecure when `listen` is not a
// loopback address (nor a Unix socket) and neither TLS nor `insecure` is set.
Status check_listen_exposure(const std::string& listen, bool tls, bool insecure);

// OK when `token` is empty (none required) or the call's metadata carries
// "authorization: Bearer <token>"; UNAUTHENTICATED saying what was missing
// or wrong otherwise.
grpc::Status check_bearer_token(const grpc::ServerContext& context, const std::string& token);

}  // namespace outcore::server
