/* Mesh subcommand (placeholder until the mesh module lands). */
#include "cli.h"

int cmd_mesh(int argc, char **argv) {
  (void)argc;
  cli_error(argv[0], "not implemented yet");
  return CLI_INTERNAL;
}
