// `outcore serve SCENE [--listen HOST:PORT] ...`: opens a scene store and
// answers outcore.v1.SceneQuery over gRPC (with grpc.health.v1 and server
// reflection) until SIGINT/SIGTERM, then drains in-flight calls for at most
// --drain-s (10 s), cancels the batches still being traced then (through the
// engine's cancellation) and exits 0; should a call still not have ended a
// second later, it exits 1 without it. Prints "listening on HOST:PORT" on stdout once it accepts
// calls (the real port when PORT is 0); logs go to stderr (text or JSON).
// With --metrics-listen it also serves Prometheus metrics and a status page
// (metrics_http_server.h, printing "metrics on http://HOST:PORT" first); TLS,
// the bearer token and the refusal of plaintext off loopback are
// server_security.h's.
//
// Thread-safety: called once from main().
#pragma once

namespace CLI {
class App;
}

namespace outcore {

void add_serve_command(CLI::App& app, int& exit_code);

}  // namespace outcore
