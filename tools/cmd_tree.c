/* `quadkit tree`: build a tree over a points file and print its statistics as JSON. */
#include <stdlib.h>
#include <string.h>

#include "cli.h"

static void usage(FILE *f) {
  fprintf(f,
          "usage: quadkit tree POINTS.csv [--xy X,Y] [--capacity C] [--max-depth D] [--svg FILE]\n"
          "Builds a point-region quadtree and prints its statistics as one JSON object.\n"
          "  --capacity C   points a leaf holds before it splits (default 1)\n"
          "  --max-depth D  depth cap for coincident points (default %d, at most %d)\n"
          "  --svg FILE     also draw the tree\n"
          "  --xy X,Y       the columns holding x and y: header names or 1-based numbers\n"
          "                 (default: the first two)\n",
          QK_DEFAULT_MAX_DEPTH, QK_MAX_DEPTH_LIMIT);
}

int cmd_tree(int argc, char **argv) {
  const char *cmd = "tree", *in = NULL, *svg = NULL, *xy = NULL;
  unsigned long capacity = 1, depth = QK_DEFAULT_MAX_DEPTH;
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
      usage(stdout);
      return CLI_OK;
    } else if (!strcmp(argv[i], "--capacity")) {
      if (cli_parse_u32(cmd, "--capacity", i + 1 < argc ? argv[++i] : NULL, 1, UINT32_MAX,
                        &capacity))
        return CLI_USAGE;
    } else if (!strcmp(argv[i], "--max-depth")) {
      if (cli_parse_u32(cmd, "--max-depth", i + 1 < argc ? argv[++i] : NULL, 1, QK_MAX_DEPTH_LIMIT,
                        &depth))
        return CLI_USAGE;
    } else if (!strcmp(argv[i], "--xy")) {
      if (cli_parse_xy(cmd, "--xy", i + 1 < argc ? argv[++i] : NULL, &xy)) return CLI_USAGE;
    } else if (!strcmp(argv[i], "--svg")) {
      if (i + 1 >= argc) {
        cli_error(cmd, "--svg needs a file name");
        return CLI_USAGE;
      }
      svg = argv[++i];
    } else if (argv[i][0] == '-' && argv[i][1]) {
      cli_error(cmd, "unknown option '%s' (see quadkit tree --help)", argv[i]);
      return CLI_USAGE;
    } else if (!in) {
      in = argv[i];
    } else {
      cli_error(cmd, "unexpected argument '%s'", argv[i]);
      return CLI_USAGE;
    }
  }
  if (!in) {
    usage(stderr);
    return CLI_USAGE;
  }
  /* Standard output (the statistics) and the picture's file are opened first, before the
   * points are read (the input noted first, so that an output naming it, or its pipe, is
   * still refused): a path that cannot be written is an error at once (it came after
   * reading and building, 1.5 s on 10^6 points; before that, after the statistics were
   * printed), and `--svg /dev/stdout` or `--svg -` beside the statistics is refused (the
   * JSON went after the SVG). */
  cli_note_input(in);
  cli_out_t so, o;
  int rc;
  if ((rc = cli_out_open(cmd, "-", &so)) || (svg && (rc = cli_out_open(cmd, svg, &o)))) {
    cli_out_close(cmd, &so, 0);
    return rc;
  }
  qk_point_t *pts;
  size_t n;
  qk_tree_t *tree = NULL;
  rc = cli_read_points(in, xy, NULL, &pts, &n);
  if (!rc) {
    qk_tree_options_t opt;
    qk_tree_options_init(&opt);
    opt.capacity = (uint32_t)capacity;
    opt.max_depth = (uint32_t)depth;
    rc = cli_build_tree(cmd, cli_input_name(in), pts, n, &opt, &tree);
    free(pts);
  }
  if (rc) { /* (nothing written: a file's temporary removed) */
    if (svg) cli_out_close(cmd, &o, 0);
    cli_out_close(cmd, &so, 0);
    return rc;
  }
  if (svg) {
    qk_status_t st = qk_tree_write_svg(tree, o.f, 800);
    if (st == QK_OK && (fflush(o.f) != 0 || ferror(o.f))) st = QK_ERR_IO;
    if (st == QK_ERR_IO && ferror(o.f))
      rc = CLI_INTERNAL; /* (said when the picture is closed) */
    else if (st)
      rc = cli_status(cmd, svg, st);
  }
  /* The statistics once the picture is written (a command that failed printed them: exit 3
   * with the JSON on stdout, as if it had worked), and out before the picture is renamed
   * into place: when standard output fails, the picture is not left behind. */
  if (!rc) {
    qk_tree_stats_t s;
    qk_tree_stats(tree, &s);
    printf("{\"points\": %zu, \"nodes\": %zu, \"leaves\": %zu, \"height\": %u, "
           "\"max_leaf_points\": %zu, \"capped_leaves\": %zu, \"capacity\": %u, \"max_depth\": %u, "
           "\"root\": {\"x\": %.17g, \"y\": %.17g, \"side\": %.17g}, \"memory_bytes\": %zu}\n",
           s.points, s.nodes, s.leaves, s.height, s.max_leaf_points, s.capped_leaves, s.capacity,
           s.max_depth, s.root.x + 0.0, s.root.y + 0.0, s.root.side /* (-0 as 0) */,
           s.memory_bytes); /* (so: standard output) */
  }
  int rc2 = cli_out_close(cmd, &so, rc == CLI_OK);
  if (!rc) rc = rc2;
  if (svg) {
    rc2 = cli_out_close(cmd, &o, rc == CLI_OK);
    if (!rc) rc = rc2;
  }
  qk_tree_free(tree);
  return rc;
}
