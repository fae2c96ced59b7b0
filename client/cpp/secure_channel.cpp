#include "client/cpp/secure_channel.h"

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/client_interceptor.h>

#include <vector>

#include "core/io/npy.h"

namespace outcore::client {

namespace {

class BearerTokenInterceptor final : public grpc::experimental::Interceptor {
 public:
  explicit BearerTokenInterceptor(const std::string& header) : header_(header) {}
  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            grpc::experimental::InterceptionHookPoints::PRE_SEND_INITIAL_METADATA)) {
      methods->GetSendInitialMetadata()->insert({"authorization", header_});
    }
    methods->Proceed();
  }

 private:
  const std::string& header_;  // the factory's, which the channel keeps alive
};

class BearerTokenInterceptorFactory final : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  explicit BearerTokenInterceptorFactory(const std::string& token) : header_("Bearer " + token) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(grpc::experimental::ClientRpcInfo*) override {
    return new BearerTokenInterceptor(header_);
  }

 private:
  std::string header_;
};

Expected<std::shared_ptr<grpc::ChannelCredentials>> credentials_of(const ChannelSecurity& security) {
  if (!security.tls()) {
    if (!security.tls_cert_file.empty() || !security.tls_key_file.empty()) {
      return invalid_argument("a client certificate (--tls-cert/--tls-key) needs TLS: give --tls-ca too");
    }
    return grpc::InsecureChannelCredentials();
  }
  if (security.tls_cert_file.empty() != security.tls_key_file.empty()) {
    return invalid_argument("a client certificate needs both --tls-cert and --tls-key");
  }
  grpc::SslCredentialsOptions options;
  OUTCORE_ASSIGN_OR_RETURN(options.pem_root_certs, read_whole_file(security.tls_ca_file));
  if (options.pem_root_certs.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
    return invalid_argument("--tls-ca " + security.tls_ca_file + " holds no PEM certificate");
  }
  if (!security.tls_cert_file.empty()) {
    OUTCORE_ASSIGN_OR_RETURN(options.pem_cert_chain, read_whole_file(security.tls_cert_file));
    OUTCORE_ASSIGN_OR_RETURN(options.pem_private_key, read_whole_file(security.tls_key_file));
  }
  return grpc::SslCredentials(options);
}

}  // namespace

Expected<std::shared_ptr<grpc::Channel>> make_channel(const std::string& address,
                                                      const ChannelSecurity& security,
                                                      const grpc::ChannelArguments& arguments) {
  OUTCORE_ASSIGN_OR_RETURN(std::shared_ptr<grpc::ChannelCredentials> credentials, credentials_of(security));
  if (security.auth_token.empty()) return grpc::CreateCustomChannel(address, credentials, arguments);
  std::vector<std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(std::make_unique<BearerTokenInterceptorFactory>(security.auth_token));
  return grpc::experimental::CreateCustomChannelWithInterceptors(address, credentials, arguments,
                                                                 std::move(interceptors));
}

}  // namespace outcore::client
