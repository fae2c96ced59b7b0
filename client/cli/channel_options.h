// The connection flags every remote subcommand takes (query, health):
// --tls-ca, --tls-cert, --tls-key and --auth-token-file, turned into the
// client's ChannelSecurity (the token read from its file).
//
// Thread-safety: called from main()'s thread only.
#pragma once

#include <string>

#include "client/cpp/secure_channel.h"
#include "core/util/status.h"

namespace CLI {
class App;
}

namespace outcore {

struct ChannelSecurityArgs {
  std::string tls_ca;
  std::string tls_cert;
  std::string tls_key;
  std::string auth_token_file;
};

void add_channel_security_options(CLI::App& command, ChannelSecurityArgs& args);

// The security the flags ask for; the token file's errors name the flag.
Expected<client::ChannelSecurity> channel_security_of(const ChannelSecurityArgs& args);

}  // namespace outcore
