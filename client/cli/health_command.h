// `outcore health --server HOST:PORT [--service NAME]`: asks the server's
// grpc.health.v1 service and exits 0 when it answers SERVING, 1 otherwise
// (printing what it answered or why it could not be asked). For container
// HEALTHCHECKs and scripts that wait for a server; Kubernetes probes can use
// their own gRPC probe on the same service.
//
// Thread-safety: called once from main().
#pragma once

namespace CLI {
class App;
}

namespace outcore {

void add_health_command(CLI::App& app, int& exit_code);

}  // namespace outcore
