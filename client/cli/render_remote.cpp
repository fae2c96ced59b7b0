#include "client/cli/render_remote.h"

#include <memory>
#include <utility>

#include "client/cli/channel_options.h"
#include "client/cpp/scene_client.h"

namespace outcore {

Expected<TraceRays> connect_render_server(const RemoteRenderOptions& options) {
  client::ConnectOptions connect_options;
  if (options.deadline_seconds > 0) connect_options.timeout_seconds = options.deadline_seconds;
  connect_options.shared_memory = options.shared_memory;
  OUTCORE_ASSIGN_OR_RETURN(connect_options.security,
                           channel_security_of(ChannelSecurityArgs{
                               options.tls_ca, options.tls_cert, options.tls_key, options.auth_token_file}));
  OUTCORE_ASSIGN_OR_RETURN(std::unique_ptr<client::SceneClient> connected,
                           client::SceneClient::connect(options.server, connect_options));
  // Shared: std::function needs a copyable target.
  std::shared_ptr<client::SceneClient> scene = std::move(connected);
  client::CallOptions call;
  call.deadline_seconds = options.deadline_seconds;
  return TraceRays([scene, call](std::span<const Ray> rays, std::span<Hit> hits) {
    return scene->intersect(rays, hits, call);
  });
}

}  // namespace outcore
