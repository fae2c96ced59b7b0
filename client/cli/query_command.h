// `outcore query --server HOST:PORT --rays R.npy -o H.npy [--any-hit] ...`:
// the remote twin of `outcore trace`, through the C++ client library (same
// files, bitwise the same answers on the same store).
//
// Thread-safety: called once from main().
#pragma once

namespace CLI {
class App;
}

namespace outcore {

void add_query_command(CLI::App& app, int& exit_code);

}  // namespace outcore
