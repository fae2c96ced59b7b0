#include "server/server_security.h"

#include <grpcpp/security/server_credentials.h>

#include "core/io/bearer_token_file.h"
#include "core/io/npy.h"
#include "core/util/loopback_address.h"

namespace outcore::server {

Expected<std::shared_ptr<grpc::ServerCredentials>> server_credentials(const TlsFiles& tls) {
  if (!tls.enabled()) {
    if (!tls.client_ca.empty()) return invalid_argument("--tls-client-ca needs --tls-cert and --tls-key");
    return grpc::InsecureServerCredentials();
  }
  if (tls.cert.empty()) return invalid_argument("--tls-key needs --tls-cert (the server's certificate)");
  if (tls.key.empty()) return invalid_argument("--tls-cert needs --tls-key (the certificate's private key)");
  grpc::SslServerCredentialsOptions options;
  grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
  OUTCORE_ASSIGN_OR_RETURN(pair.cert_chain, read_whole_file(tls.cert));
  OUTCORE_ASSIGN_OR_RETURN(pair.private_key, read_whole_file(tls.key));
  // gRPC would only fail at the first handshake; a file that is not PEM at
  // all is refused now, naming it.
  if (pair.cert_chain.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
    return invalid_argument("--tls-cert " + tls.cert + " holds no PEM certificate");
  }
  if (pair.private_key.find("PRIVATE KEY-----") == std::string::npos) {
    return invalid_argument("--tls-key " + tls.key + " holds no PEM private key");
  }
  options.pem_key_cert_pairs.push_back(std::move(pair));
  if (!tls.client_ca.empty()) {
    OUTCORE_ASSIGN_OR_RETURN(options.pem_root_certs, read_whole_file(tls.client_ca));
    if (options.pem_root_certs.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
      return invalid_argument("--tls-client-ca " + tls.client_ca + " holds no PEM certificate");
    }
    options.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(options);
}

Status check_listen_exposure(const std::string& listen, bool tls, bool insecure) {
  if (tls || insecure) return Status::Ok();
  if (listen.starts_with("unix:") || listen.starts_with("unix-abstract:")) return Status::Ok();
  if (is_loopback_host(host_of(listen))) return Status::Ok();
  return invalid_argument(
      "--listen " + listen +
      " is not a loopback address: serving it in plaintext would let anyone on the network "
      "query the scene unencrypted. Give --tls-cert and --tls-key, or --insecure to serve "
      "plaintext anyway (e.g. inside a private container network)");
}

grpc::Status check_bearer_token(const grpc::ServerContext& context, const std::string& token) {
  if (token.empty()) return grpc::Status::OK;
  const auto& metadata = context.client_metadata();
  const auto found = metadata.find(kAuthorizationKey);
  if (found == metadata.end()) {
    return {grpc::StatusCode::UNAUTHENTICATED,
            "this server requires a bearer token (metadata \"authorization: Bearer TOKEN\"; "
            "query --auth-token-file, Python SceneClient(token=...))"};
  }
  const std::string_view value(found->second.data(), found->second.size());
  const std::string_view prefix(kBearerPrefix);
  if (!value.starts_with(prefix)) {
    return {grpc::StatusCode::UNAUTHENTICATED,
            "the authorization metadata is not of the form \"Bearer TOKEN\""};
  }
  if (!tokens_equal(value.substr(prefix.size()), token)) {
    return {grpc::StatusCode::UNAUTHENTICATED, "the bearer token is not the one this server requires"};
  }
  return grpc::Status::OK;
}

}  // namespace outcore::server
