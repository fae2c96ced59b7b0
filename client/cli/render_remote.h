// The remote half of `outcore render --server HOST:PORT` (the command lives
// in core/cli/render_command.cpp, which cannot see gRPC): connects the C++
// client and returns its closest-hit call as the command's TraceRays.
//
// Thread-safety: the returned TraceRays may be called from several threads
// (SceneClient is thread-safe).
#pragma once

#include "core/cli/render_command.h"

namespace outcore {

Expected<TraceRays> connect_render_server(const RemoteRenderOptions& options);

}  // namespace outcore
