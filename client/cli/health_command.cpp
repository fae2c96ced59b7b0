#include "client/cli/health_command.h"

#include <grpcpp/client_context.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "client/cli/channel_options.h"
#include "client/cpp/scene_client.h"
#include "core/cli/commands.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "proto/outcore/v1/grpc_code_names.h"

namespace outcore {

namespace {

struct HealthArgs {
  std::string server = "127.0.0.1:50051";
  std::string service;  // "": the server as a whole
  double timeout_seconds = 5;
  ChannelSecurityArgs security;
};

int run_health(const HealthArgs& args) {
  if (!(args.timeout_seconds > 0 && args.timeout_seconds <= 3600)) {
    return report_command_error("health", "--timeout-s must be more than 0 and at most 3600");
  }
  const Status ports = client::check_target_ports(args.server);
  if (!ports.ok()) return report_command_error("health", ports.message());
  auto security = channel_security_of(args.security);
  if (!security.ok()) return report_command_error("health", security.status().message());
  auto channel = client::make_channel(args.server, *security, grpc::ChannelArguments());
  if (!channel.ok()) return report_command_error("health", channel.status().message());
  auto stub = grpc::health::v1::Health::NewStub(*channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::duration_cast<std::chrono::milliseconds>(
                           std::chrono::duration<double>(args.timeout_seconds)));
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(args.service);
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status = stub->Check(&context, request, &response);
  const std::string what = args.server + (args.service.empty() ? "" : " service " + args.service);
  if (!status.ok()) {
    return report_command_error(
        "health", what + ": " + wire::grpc_code_name(status.error_code()) + ": " + status.error_message());
  }
  const std::string answer = grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response.status());
  std::printf("%s: %s\n", what.c_str(), answer.c_str());
  return response.status() == grpc::health::v1::HealthCheckResponse::SERVING ? 0 : 1;
}

}  // namespace

void add_health_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<HealthArgs>();
  CLI::App* cmd = app.add_subcommand("health", "Ask a server's health service; exit 0 when it is SERVING");
  cmd->add_option("--server", args->server, "HOST:PORT of the server")->capture_default_str();
  cmd->add_option("--service", args->service, "Service name to ask about (default: the server as a whole)");
  cmd->add_option("--timeout-s", args->timeout_seconds, "Give up after this many seconds")
      ->capture_default_str();
  add_channel_security_options(*cmd, args->security);
  cmd->callback([args, &exit_code] { exit_code = run_health(*args); });
}

}  // namespace outcore
