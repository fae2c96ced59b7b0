// The `outcore` command: one binary whose subcommands are implemented in the
// component they belong to (core: pack, info, trace, render; server: serve;
// client: query, health and render's remote half).
#include <malloc.h>

#include <CLI/CLI.hpp>

#include "client/cli/health_command.h"
#include "client/cli/query_command.h"
#include "client/cli/render_remote.h"
#include "core/cli/commands.h"
#include "core/cli/render_command.h"
#include "core/util/huge_page_heap.h"
#include "server/serve_command.h"

int main(int argc, char** argv) {
  outcore::reexec_with_huge_page_heap(argv);
  // One malloc arena for the whole process. Brick builds and evictions free
  // megabytes on one thread that another allocates next; with glibc's
  // per-thread arenas that memory stayed with the arena that freed it, and
  // under a tight cache budget the process held ~35% more than the budget
  // beyond its fixed overhead (measured: peak RSS 279 -> 234 MiB at a 129 MiB
  // budget, docs/BENCHMARKS.md). Hot loops never allocate, so sharing the
  // arena costs nothing measurable.
  mallopt(M_ARENA_MAX, 1);
  CLI::App app{"Outcore: out-of-core scene query service for ray tracing"};
  app.require_subcommand(1);
  app.set_version_flag("--version", OUTCORE_VERSION);
  int exit_code = 1;
  outcore::add_pack_command(app, exit_code);
  outcore::add_info_command(app, exit_code);
  outcore::add_trace_command(app, exit_code);
  outcore::add_stress_command(app, exit_code);
  outcore::add_cache_sim_command(app, exit_code);
  outcore::add_calibrate_command(app, exit_code);
  outcore::add_serve_command(app, exit_code);
  outcore::add_query_command(app, exit_code);
  outcore::add_health_command(app, exit_code);
  outcore::add_render_command(app, exit_code, outcore::connect_render_server);
  CLI11_PARSE(app, argc, argv);
  return exit_code;
}
