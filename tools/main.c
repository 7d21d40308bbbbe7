/* The `quadkit` command-line tool: dispatches to one subcommand. */
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "cli.h"

typedef struct command {
  const char *name;
  int (*run)(int argc, char **argv);
  const char *synopsis;
} command_t;

static const command_t commands[] = {
    {"tree", cmd_tree, "tree POINTS.csv [--capacity C] [options]     build a tree, print stats"},
    {"knn", cmd_knn, "knn POINTS.csv QUERIES.csv -k K               k nearest neighbours"},
    {"range", cmd_range, "range POINTS.csv BOXES.csv                   points in boxes"},
    {"radius", cmd_radius, "radius POINTS.csv QUERIES.csv -r R            points within R"},
    {"locate", cmd_locate, "locate POINTS.csv QUERIES.csv                leaf holding each query"},
    {"collide", cmd_collide,
     "collide DISCS.csv                             overlapping disc pairs"},
    {"raycast", cmd_raycast, "raycast DISCS.csv RAYS.csv                   first disc hit by rays"},
    {"geo", cmd_geo, "geo knn|radius POINTS.csv QUERIES.csv ...     geodesic queries (WGS84)"},
    {"world", cmd_world,
     "world OBJECTS.csv MOVES.csv [--pairs all|began|ended]  replay moving objects"},
    {"simulate", cmd_simulate,
     "simulate [--n N] [--frames F] [--seed S] [--svg FILE]  bouncing objects"},
    {"mesh", cmd_mesh, "mesh IN.poly|IN.geojson -o PREFIX [options]   quadtree mesh generator"},
    {"join", cmd_join, "join REGIONS POINTS.csv [--field NAME]...     feature holding each point"},
    {"regions", cmd_regions,
     "regions REGIONS [--stats] [--svg FILE]       polygon layer statistics"},
};

static void usage(FILE *f) {
  fprintf(f, "usage: quadkit COMMAND [ARGS]\n\ncommands:\n");
  for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
    fprintf(f, "  %s\n", commands[i].synopsis);
  fprintf(f, "\nEvery command accepts --help. Points CSV: x and y are the first two fields of "
             "each line,\nor the columns named by --xy X,Y (header names or 1-based numbers). "
             "The first line is\na header when neither its x nor its y field is a number, or "
             "when --xy gives\nnames. A point's id is its 0-based data row. Limits: a line of CSV "
             "or .poly\ninput may hold at most 1 MiB (1048576 bytes); a NUL byte is refused "
             "as binary data;\nan input from a pipe or device is read to at most 2^31 - 1 "
             "bytes.\nAn input named - is standard input (a pipe or terminal may be named "
             "as one input only).\n\nexit status: 0 "
             "success, 1 bad "
             "input, 2 usage error, 3 internal error or out of memory\n");
}

/* Output that could not be written (a full disk, /dev/full, a closed pipe) is an error,
 * whichever command printed it. */
static int finish(int rc) {
  if (fflush(stdout) != 0 || ferror(stdout)) {
    if (rc == CLI_OK) cli_msg("quadkit: cannot write standard output: %s\n", strerror(errno));
    return rc == CLI_OK ? CLI_INTERNAL : rc;
  }
  return rc;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    usage(stderr);
    return CLI_USAGE;
  }
  if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h") || !strcmp(argv[1], "help")) {
    usage(stdout);
    return finish(CLI_OK);
  }
  for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
    if (!strcmp(argv[1], commands[i].name)) return finish(commands[i].run(argc - 1, argv + 1));
  cli_msg("quadkit: unknown command '%s' (see quadkit --help)\n", argv[1]);
  return CLI_USAGE;
}
