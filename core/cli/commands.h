// The engine-side subcommands of the `outcore` binary (pack, info, ...). Each
// adds itself to the CLI11 app; when selected, its callback runs and stores the
// process exit code (0 success, 1 a failure the message explains).
//
// Thread-safety: called once from main().
#pragma once

#include <string>

namespace CLI {
class App;
}

namespace outcore {

void add_pack_command(CLI::App& app, int& exit_code);
void add_info_command(CLI::App& app, int& exit_code);
void add_trace_command(CLI::App& app, int& exit_code);
void add_stress_command(CLI::App& app, int& exit_code);
void add_cache_sim_command(CLI::App& app, int& exit_code);
void add_calibrate_command(CLI::App& app, int& exit_code);

// Prints "outcore <command>: error: <message>" on stderr and returns 1.
int report_command_error(const char* command, const std::string& message);

}  // namespace outcore
