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
    "usage: quadkit mesh IN.poly -o PREFIX [--size U] [--svg FILE] [--msh FILE]\n"
    "                    [--vtk FILE] [--stats]\n"
    "\n"
    "Mesh disjoint polygons with integer vertices and edges at 0, 45, 90 or 135 degrees\n"
    "(Triangle's .poly format) over the domain [0,U]^2 with the quadtree algorithm of\n"
    "de Berg et al., ch. 14: every angle is between 45 and 90 degrees.\n"
    "\n"
    "  -o PREFIX     write PREFIX.node and PREFIX.ele (Triangle's formats, the input's\n"
    "                first index, component id as the triangle attribute)\n"
    "  --size U      domain side, a power of two (default: the smallest power of two\n"
    "                >= every coordinate)\n"
    "  --svg FILE    picture of the components, quadtree leaves and triangles\n"
    "  --msh FILE    gmsh 4.1 ASCII mesh, one physical group per component\n"
    "  --vtk FILE    VTK XML unstructured grid (.vtu), component id as cell data\n"
    "  --stats       print figures as one JSON object on stdout\n"
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

int cmd_mesh(int argc, char **argv) {
  const char *cmd = argv[0];
  const char *in = NULL, *prefix = NULL, *svg = NULL, *msh = NULL, *vtk = NULL;
  unsigned long size = 0;
  int stats = 0;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
      fputs(usage_text, stdout);
      return CLI_OK;
    }
    int has_val = i + 1 < argc;
    if (!strcmp(a, "-o") || !strcmp(a, "--svg") || !strcmp(a, "--msh") || !strcmp(a, "--vtk") ||
        !strcmp(a, "--size")) {
      if (!has_val) {
        cli_error(cmd, "%s needs a value", a);
        return usage(cmd, NULL);
      }
      const char *v = argv[++i];
      if (!strcmp(a, "-o")) prefix = v;
      if (!strcmp(a, "--svg")) svg = v;
      if (!strcmp(a, "--msh")) msh = v;
      if (!strcmp(a, "--vtk")) vtk = v;
      if (!strcmp(a, "--size")) {
        if (cli_parse_u32(cmd, "--size", v, 1, 1ul << 30, &size)) return CLI_USAGE;
        if (size & (size - 1)) {
          cli_error(cmd, "--size must be a power of two, not %lu", size);
          return CLI_USAGE;
        }
      }
    } else if (!strcmp(a, "--stats")) {
      stats = 1;
    } else if (a[0] == '-' && a[1]) {
      cli_error(cmd, "unknown option '%s'", a);
      return usage(cmd, NULL);
    } else if (!in) {
      in = a;
    } else {
      return usage(cmd, "more than one input file");
    }
  }
  if (!in) return usage(cmd, "no input file");
  if (!prefix) return usage(cmd, "-o PREFIX is required");

  FILE *f = strcmp(in, "-") ? fopen(in, "rb") : stdin;
  if (!f) {
    cli_error(cmd, "cannot open %s", in);
    return CLI_BAD_INPUT;
  }
  qk_poly_t *poly = NULL;
  qk_mesh_error_t err;
  double t_read = now();
  qk_status_t st = qk_poly_read(f, NULL, &poly, &err);
  t_read = now() - t_read;
  if (f != stdin) fclose(f);
  if (st == QK_OK) {
    qk_mesh_options_t opt;
    qk_mesh_options_init(&opt);
    opt.size = size;
    qk_mesh_t *mesh = NULL;
    st = qk_mesh_generate(poly, &opt, &mesh, &err);
    if (st == QK_OK) {
      /* Every output goes to a temporary file first; all are renamed only when all were
       * written, so a failure leaves nothing behind. */
      size_t plen = strlen(prefix);
      char *node_path = malloc(plen + 6), *ele_path = malloc(plen + 5);
      int rc = CLI_OK;
      double t_write = now();
      if (!node_path || !ele_path) {
        cli_error(cmd, "out of memory");
        rc = CLI_INTERNAL;
      } else {
        memcpy(node_path, prefix, plen);
        memcpy(node_path + plen, ".node", 6);
        memcpy(ele_path, prefix, plen);
        memcpy(ele_path + plen, ".ele", 5);
        struct {
          const char *path;
          writer_fn fn;
          cli_out_t out;
        } outs[5] = {{node_path, w_node, {0}},
                     {ele_path, w_ele, {0}},
                     {svg, w_svg, {0}},
                     {msh, w_msh, {0}},
                     {vtk, w_vtu, {0}}};
        int opened = 0;
        for (int k = 0; k < 5 && rc == CLI_OK; k++) {
          if (!outs[k].path) continue;
          if ((rc = cli_out_open(cmd, outs[k].path, &outs[k].out)) != CLI_OK) break;
          opened = k + 1;
          qk_status_t ws = outs[k].fn(mesh, outs[k].out.f, qk_poly_first_index(poly));
          if (ws != QK_OK) rc = cli_status(cmd, outs[k].path, ws);
        }
        for (int k = 0; k < opened; k++) {
          if (!outs[k].path || !outs[k].out.f) continue;
          int c = cli_out_close(cmd, &outs[k].out, rc == CLI_OK);
          if (rc == CLI_OK) rc = c;
        }
      }
      free(node_path);
      free(ele_path);
      t_write = now() - t_write;
      if (rc == CLI_OK && stats) {
        qk_mesh_stats_t s;
        qk_mesh_stats(mesh, &s);
        printf("{\"U\": %llu, \"components\": %zu, \"leaves_before_balance\": %zu, "
               "\"leaves\": %zu, \"triangles\": %zu, \"vertices\": %zu, \"steiner\": %zu, "
               "\"min_angle_deg\": %.10g, \"max_angle_deg\": %.10g, \"uniform_triangles\": %.0f, "
               "\"seconds\": {\"read\": %.6f, \"validate\": %.6f, \"subdivide\": %.6f, "
               "\"balance\": %.6f, \"triangulate\": %.6f, \"write\": %.6f}}\n",
               (unsigned long long)s.size, s.components, s.leaves_before_balance, s.leaves,
               s.triangles, s.vertices, s.steiner, s.min_angle_deg, s.max_angle_deg,
               s.uniform_triangles, t_read, s.seconds_validate, s.seconds_subdivide,
               s.seconds_balance, s.seconds_triangulate, t_write);
      }
      qk_mesh_free(mesh);
      qk_poly_free(poly);
      return rc;
    }
  }
  qk_poly_free(poly);
  const char *name = strcmp(in, "-") ? in : "<stdin>";
  if (err.line)
    cli_error(cmd, "%s:%lu: %s", name, err.line, err.message);
  else
    cli_error(cmd, "%s: %s", name, err.message[0] ? err.message : qk_strerror(st));
  return (st == QK_ERR_NOMEM || st == QK_ERR_IO) ? CLI_INTERNAL : CLI_BAD_INPUT;
}
