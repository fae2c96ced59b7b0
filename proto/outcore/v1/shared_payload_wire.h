// What both ends of a shared-payload call (scene_query.proto, SharedPayload)
// agree on beyond the messages: the trailing metadata that marks a refusal
// ("send bytes from now on", as opposed to a call that failed). The server
// sets it (server/scene_query_service.cpp); the C++ client reads it
// (client/cpp/scene_client.cpp) and the Python client's copy of it
// (client/python/src/outcore/client.py) is checked against this one by
// tests/python/test_shared.py.
//
// Thread-safety: constants.
#pragma once

namespace outcore::wire {

inline constexpr const char* kSharedRefusedKey = "outcore-shared-payload";
inline constexpr const char* kSharedRefusedValue = "refused";

}  // namespace outcore::wire
