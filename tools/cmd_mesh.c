/*
 * `quadkit mesh`: read a .poly file, mesh it, write Triangle/gmsh/VTK/SVG files. Only
 * argument handling lives here; parsing, meshing and the writers are the library's.
 */
#include "cli.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now(void) {
  struct timespec ts;
  if (timespec_get(&ts, TIME_UTC) != TIME_UTC) return 0;
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static const char *usage_text =
    "usage: quadkit mesh IN.poly -o PREFIX [--book | --dyadic] [--size U] [--max-size H]\n"
    "                    [--min-angle DEG] [--poly FILE] [--svg FILE] [--msh FILE]\n"
    "                    [--vtk FILE] [--stats]\n"
    "\n"
    "Mesh polygons with edges at 0, 45, 90 or 135 degrees (Triangle's .poly format) with\n"
    "the quadtree algorithm of de Berg et al., ch. 14: every angle is between 45 and 90\n"
    "degrees (proven). Integer vertices use the book's mode over [0,U]^2; real (dyadic)\n"
    "coordinates, or a size bound, use the same algorithm on the coarsest binary lattice\n"
    "holding every vertex exactly (the dyadic mode). Input vertices come back bit-identical.\n"
    "\n"
    "  -o PREFIX       write PREFIX.node (with boundary markers when the input has them)\n"
    "                  and PREFIX.ele (component id, then the regional attribute if any)\n"
    "  --book          insist on the book's mode (integer vertices in [0,U]^2)\n"
    "  --dyadic        insist on the dyadic-lattice mode\n"
    "  --size U        domain side for the book's mode, a power of two (default: the\n"
    "                  smallest power of two >= every coordinate)\n"
    "  --max-size H    longest triangle edge, in input units (guaranteed)\n"
    "  --min-angle DEG the smallest angle wanted: accepted up to the proven 45 degrees;\n"
    "                  prints the bound that applies on stderr\n"
    "  --poly FILE     the mesh edges along input segments, with markers (.poly)\n"
    "  --svg FILE      picture of the components, quadtree leaves and triangles\n"
    "  --msh FILE      gmsh 4.1 ASCII mesh: a physical group per component and per marker\n"
    "  --vtk FILE      VTK XML unstructured grid (.vtu): component, region, attribute,\n"
    "                  marker\n"
    "  --stats         print figures as one JSON object on stdout (with the angle\n"
    "                  histogram in 1-degree bins)\n"
    "  IN.poly may be '-' for standard input.\n"
    "\n"
    "Exit status: 0 ok, 1 bad input (FILE:LINE: reason on stderr; nothing written),\n"
    "2 usage error, 3 internal error or out of memory.\n";

static int usage(const char *cmd, const char *msg) {
  if (msg) cli_error(cmd, "%s", msg);
  fputs(usage_text, stderr);
  return CLI_USAGE;
}

/* Write one output through a temporary file; returns CLI_OK or an exit code. */
typedef qk_status_t (*writer_fn)(const qk_mesh_t *m, FILE *f, unsigned arg);

static qk_status_t w_node(const qk_mesh_t *m, FILE *f, unsigned a) {
  return qk_mesh_write_node(m, f, a);
}
static qk_status_t w_ele(const qk_mesh_t *m, FILE *f, unsigned a) {
  return qk_mesh_write_ele(m, f, a);
}
static qk_status_t w_poly(const qk_mesh_t *m, FILE *f, unsigned a) {
  return qk_mesh_write_poly(m, f, a);
}
static qk_status_t w_msh(const qk_mesh_t *m, FILE *f, unsigned a) {
  (void)a;
  return qk_mesh_write_msh(m, f);
}
static qk_status_t w_vtu(const qk_mesh_t *m, FILE *f, unsigned a) {
  (void)a;
  return qk_mesh_write_vtu(m, f);
}
static qk_status_t w_svg(const qk_mesh_t *m, FILE *f, unsigned a) {
  (void)a;
  return qk_mesh_write_svg(m, f, 0);
}

/* The command line. */
typedef struct mesh_args {
  const char *in, *prefix, *svg, *msh, *vtk, *poly;
  unsigned long size;
  double max_size, min_angle;
  qk_mesh_mode_t mode;
  int stats, help;
} mesh_args_t;

/* Parse one option taking a value; returns CLI_OK or an exit code. */
static int parse_value(const char *cmd, const char *a, const char *v, mesh_args_t *o) {
  if (!strcmp(a, "-o")) o->prefix = v;
  if (!strcmp(a, "--svg")) o->svg = v;
  if (!strcmp(a, "--msh")) o->msh = v;
  if (!strcmp(a, "--vtk")) o->vtk = v;
  if (!strcmp(a, "--poly")) o->poly = v;
  if (!strcmp(a, "--size")) {
    if (cli_parse_u32(cmd, "--size", v, 1, 1ul << 30, &o->size)) return CLI_USAGE;
    if (o->size & (o->size - 1)) {
      cli_error(cmd, "--size must be a power of two, not %lu", o->size);
      return CLI_USAGE;
    }
  }
  if (!strcmp(a, "--max-size")) {
    if (cli_parse_double(cmd, "--max-size", v, &o->max_size)) return CLI_USAGE;
    if (!(o->max_size > 0)) {
      cli_error(cmd, "--max-size must be a positive length, not %s", v);
      return CLI_USAGE;
    }
  }
  if (!strcmp(a, "--min-angle")) {
    if (cli_parse_double(cmd, "--min-angle", v, &o->min_angle)) return CLI_USAGE;
    if (!(o->min_angle >= 0 && o->min_angle <= 45)) {
      cli_error(cmd,
                "--min-angle %s: the proven bound is 45 degrees (every angle in [45, 90] in "
                "both modes); nothing above it is promised",
                v);
      return CLI_USAGE;
    }
  }
  return CLI_OK;
}

static int parse_args(const char *cmd, int argc, char **argv, mesh_args_t *o) {
  memset(o, 0, sizeof *o);
  o->min_angle = -1;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
      o->help = 1;
      return CLI_OK;
    }
    static const char *valued[] = {"-o",     "--svg",  "--msh",      "--vtk",
                                   "--poly", "--size", "--max-size", "--min-angle"};
    int takes = 0;
    for (size_t k = 0; k < sizeof valued / sizeof *valued; k++) takes |= !strcmp(a, valued[k]);
    if (takes) {
      if (i + 1 >= argc) {
        cli_error(cmd, "%s needs a value", a);
        return usage(cmd, NULL);
      }
      int rc = parse_value(cmd, a, argv[++i], o);
      if (rc) return rc;
    } else if (!strcmp(a, "--stats")) {
      o->stats = 1;
    } else if (!strcmp(a, "--book") || !strcmp(a, "--dyadic")) {
      qk_mesh_mode_t md = a[2] == 'b' ? QK_MESH_BOOK : QK_MESH_DYADIC;
      if (o->mode && o->mode != md) return usage(cmd, "--book and --dyadic exclude each other");
      o->mode = md;
    } else if (a[0] == '-' && a[1]) {
      cli_error(cmd, "unknown option '%s'", a);
      return usage(cmd, NULL);
    } else if (!o->in) {
      o->in = a;
    } else {
      return usage(cmd, "more than one input file");
    }
  }
  if (!o->in) return usage(cmd, "no input file");
  if (!o->prefix) return usage(cmd, "-o PREFIX is required");
  if (o->mode == QK_MESH_DYADIC && o->size)
    return usage(cmd, "--size is the book's domain; the dyadic mode uses the input's extent");
  return CLI_OK;
}

/* Write every output through temporary files, renamed only when all were written, so a
 * failure leaves nothing behind. */
static int write_outputs(const char *cmd, const mesh_args_t *o, const qk_mesh_t *mesh,
                         unsigned first) {
  size_t plen = strlen(o->prefix);
  char *node_path = malloc(plen + 6), *ele_path = malloc(plen + 5);
  int rc = CLI_OK;
  if (!node_path || !ele_path) {
    cli_error(cmd, "out of memory");
    free(node_path);
    free(ele_path);
    return CLI_INTERNAL;
  }
  memcpy(node_path, o->prefix, plen);
  memcpy(node_path + plen, ".node", 6);
  memcpy(ele_path, o->prefix, plen);
  memcpy(ele_path + plen, ".ele", 5);
  struct {
    const char *path;
    writer_fn fn;
    cli_out_t out;
  } outs[6] = {{node_path, w_node, {0}}, {ele_path, w_ele, {0}}, {o->svg, w_svg, {0}},
               {o->msh, w_msh, {0}},     {o->vtk, w_vtu, {0}},   {o->poly, w_poly, {0}}};
  int opened = 0;
  for (int k = 0; k < 6 && rc == CLI_OK; k++) {
    if (!outs[k].path) continue;
    if ((rc = cli_out_open(cmd, outs[k].path, &outs[k].out)) != CLI_OK) break;
    opened = k + 1;
    qk_status_t ws = outs[k].fn(mesh, outs[k].out.f, first);
    if (ws != QK_OK) rc = cli_status(cmd, outs[k].path, ws);
  }
  for (int k = 0; k < opened; k++) {
    if (!outs[k].path || !outs[k].out.f) continue;
    int c = cli_out_close(cmd, &outs[k].out, rc == CLI_OK);
    if (rc == CLI_OK) rc = c;
  }
  free(node_path);
  free(ele_path);
  return rc;
}

static void print_stats(const qk_mesh_t *mesh, double t_read, double t_write) {
  qk_mesh_stats_t s;
  qk_mesh_stats(mesh, &s);
  printf("{\"U\": %llu, \"components\": %zu, \"leaves_before_balance\": %zu, "
         "\"leaves\": %zu, \"triangles\": %zu, \"vertices\": %zu, \"steiner\": %zu, "
         "\"min_angle_deg\": %.10g, \"max_angle_deg\": %.10g, \"uniform_triangles\": %.0f, "
         "\"seconds\": {\"read\": %.6f, \"validate\": %.6f, \"subdivide\": %.6f, "
         "\"balance\": %.6f, \"triangulate\": %.6f, \"write\": %.6f}, ",
         (unsigned long long)s.size, s.components, s.leaves_before_balance, s.leaves, s.triangles,
         s.vertices, s.steiner, s.min_angle_deg, s.max_angle_deg, s.uniform_triangles, t_read,
         s.seconds_validate, s.seconds_subdivide, s.seconds_balance, s.seconds_triangulate,
         t_write);
  printf("\"mode\": \"%s\", \"lattice_exponent\": %d, \"origin\": [%.17g, %.17g], "
         "\"proven_min_angle_deg\": %g, \"proven_max_angle_deg\": %g, \"angle_histogram\": [",
         s.mode == QK_MESH_BOOK ? "book" : "dyadic", s.lattice_exponent, s.origin_x, s.origin_y,
         s.proven_min_angle_deg, s.proven_max_angle_deg);
  uint64_t bins[180];
  qk_mesh_angle_histogram(mesh, bins);
  for (int k = 0; k < 180; k++) printf("%s%llu", k ? ", " : "", (unsigned long long)bins[k]);
  printf("]}\n");
}

/* Read and mesh; on failure prints FILE:LINE: reason and returns an exit code. */
static int make_mesh(const char *cmd, const mesh_args_t *o, qk_poly_t **poly, qk_mesh_t **mesh,
                     double *t_read) {
  FILE *f = strcmp(o->in, "-") ? fopen(o->in, "rb") : stdin;
  if (!f) {
    cli_error(cmd, "cannot open %s", o->in);
    return CLI_BAD_INPUT;
  }
  qk_mesh_error_t err;
  *t_read = now();
  qk_status_t st = qk_poly_read(f, NULL, poly, &err);
  *t_read = now() - *t_read;
  if (f != stdin) fclose(f);
  if (st == QK_OK) {
    qk_mesh_options_t opt;
    qk_mesh_options_init(&opt);
    opt.size = o->size;
    opt.mode = o->mode;
    opt.max_size = o->max_size;
    st = qk_mesh_generate(*poly, &opt, mesh, &err);
  }
  if (st == QK_OK) return CLI_OK;
  const char *name = strcmp(o->in, "-") ? o->in : "<stdin>";
  if (err.line)
    cli_error(cmd, "%s:%lu: %s", name, err.line, err.message);
  else
    cli_error(cmd, "%s: %s", name, err.message[0] ? err.message : qk_strerror(st));
  if (st == QK_ERR_INVALID) return CLI_USAGE;
  return (st == QK_ERR_NOMEM || st == QK_ERR_IO) ? CLI_INTERNAL : CLI_BAD_INPUT;
}

int cmd_mesh(int argc, char **argv) {
  const char *cmd = argv[0];
  mesh_args_t o;
  int rc = parse_args(cmd, argc, argv, &o);
  if (rc) return rc;
  if (o.help) {
    fputs(usage_text, stdout);
    return CLI_OK;
  }
  qk_poly_t *poly = NULL;
  qk_mesh_t *mesh = NULL;
  double t_read = 0;
  rc = make_mesh(cmd, &o, &poly, &mesh, &t_read);
  if (rc == CLI_OK) {
    double t_write = now();
    rc = write_outputs(cmd, &o, mesh, qk_poly_first_index(poly));
    t_write = now() - t_write;
    if (rc == CLI_OK && o.min_angle >= 0) {
      qk_mesh_stats_t s;
      qk_mesh_stats(mesh, &s);
      fprintf(stderr,
              "quadkit mesh: %s mode: every angle in [%g, %g] degrees (proven; --min-angle %g "
              "met everywhere, small input angles included: the input has none below 45)\n",
              s.mode == QK_MESH_BOOK ? "book's" : "dyadic", s.proven_min_angle_deg,
              s.proven_max_angle_deg, o.min_angle);
    }
    if (rc == CLI_OK && o.stats) print_stats(mesh, t_read, t_write);
  }
  qk_mesh_free(mesh);
  qk_poly_free(poly);
  return rc;
}
