// The one place where the engine's Status becomes a grpc::Status: codes map
// one to one where gRPC has the same meaning; an I/O error on the server's own
// store is INTERNAL (the client cannot fix it by changing the request).
//
// Thread-safety: pure function.
#pragma once

#include <grpcpp/support/status.h>

#include "core/util/status.h"

namespace outcore::server {

grpc::Status to_grpc_status(const Status& status);

// Returns a grpc::Status expression's value from the calling function when
// it is an error.
#define OUTCORE_RETURN_IF_GRPC_ERROR(expr) \
  do {                                     \
    const grpc::Status _status = (expr);   \
    if (!_status.ok()) return _status;     \
  } while (false)

}  // namespace outcore::server
