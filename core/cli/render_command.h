// `outcore render STORE|--server ADDR --eye X,Y,Z --center X,Y,Z --up X,Y,Z
// --fov DEG --size WxH -o image.png [--mode depth|normals|ids]`: a picture of
// a scene through Open3D's pinhole camera (core/render/pinhole_camera.h),
// traced in process by the QueryEngine or by an `outcore serve` server.
//
// core/ never sees gRPC, so the remote path is given by the client layer
// (client/cli/render_remote.h) as a ConnectRenderServer: the command checks
// every option first, then asks it for a TraceRays bound to the server.
//
// Thread-safety: called once from main().
#pragma once

#include <functional>
#include <string>

#include "core/render/band_renderer.h"
#include "core/util/status.h"

namespace CLI {
class App;
}

namespace outcore {

struct RemoteRenderOptions {
  std::string server;           // HOST:PORT
  double deadline_seconds = 0;  // of each band's call; 0: none
  bool shared_memory = true;    // large batches through /dev/shm on this host
  // TLS and the bearer token (as `outcore query`'s flags; empty: none).
  std::string tls_ca;
  std::string tls_cert;
  std::string tls_key;
  std::string auth_token_file;
};

// Connects to the server and returns the closest-hit call of its scene.
using ConnectRenderServer = std::function<Expected<TraceRays>(const RemoteRenderOptions& options)>;

void add_render_command(CLI::App& app, int& exit_code, ConnectRenderServer connect);

}  // namespace outcore
