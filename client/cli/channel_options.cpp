#include "client/cli/channel_options.h"

#include <CLI/CLI.hpp>

#include "core/io/bearer_token_file.h"

namespace outcore {

void add_channel_security_options(CLI::App& command, ChannelSecurityArgs& args) {
  command.add_option("--tls-ca", args.tls_ca, "Connect with TLS, trusting this CA's certificate (PEM)");
  command.add_option("--tls-cert", args.tls_cert, "Client certificate for servers that require one (PEM)");
  command.add_option("--tls-key", args.tls_key, "The client certificate's private key (PEM)");
  command.add_option("--auth-token-file", args.auth_token_file,
                     "Send this file's token on every call (authorization: Bearer TOKEN)");
}

Expected<client::ChannelSecurity> channel_security_of(const ChannelSecurityArgs& args) {
  client::ChannelSecurity security;
  security.tls_ca_file = args.tls_ca;
  security.tls_cert_file = args.tls_cert;
  security.tls_key_file = args.tls_key;
  if (!args.auth_token_file.empty()) {
    auto token = read_bearer_token_file(args.auth_token_file);
    if (!token.ok()) return token.status().with_context("--auth-token-file");
    security.auth_token = std::move(*token);
  }
  return security;
}

}  // namespace outcore
