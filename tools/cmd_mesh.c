/*
 * `quadkit mesh`: read a .poly file or GeoJSON polygons, mesh them, write
 * Triangle/gmsh/VTK/SVG files. Only argument handling and the input's preparation
 * (projection, rounding: tools/mesh_geojson.c) live here; parsing, meshing and the
 * writers are the library's.
 */
#define _XOPEN_SOURCE 700 /* realpath, and POSIX 2008 */
#include "cli.h"
#include "mesh_geojson.h"

#include <ctype.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

static double now(void) {
  struct timespec ts;
  if (timespec_get(&ts, TIME_UTC) != TIME_UTC) return 0;
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static const char *usage_text =
    "usage: quadkit mesh IN.poly|IN.geojson -o PREFIX [--book | --dyadic | --general]\n"
    "                    [--size U] [--max-size H] [--min-angle DEG]\n"
    "                    [--project equirect] [--round 2^-q|Q|auto]\n"
    "                    [--feature N | --field NAME=VALUE]\n"
    "                    [--poly FILE] [--svg FILE] [--msh FILE] [--vtk FILE] [--stats]\n"
    "\n"
    "Mesh a planar straight-line graph: polygons with holes, internal segments, any angles\n"
    "and real coordinates. Three modes, chosen automatically unless one is insisted on:\n"
    "the book's quadtree mode (de Berg et al., ch. 14: integer vertices, edges at 0, 45, 90\n"
    "or 135 degrees; every angle in [45, 90], proven), the dyadic-lattice mode (the same on\n"
    "the coarsest binary lattice holding real coordinates), and the general mode (any\n"
    "angles: quality Delaunay refinement, its work bounded by a graded quadtree; every angle\n"
    "at least 20 degrees, proven, except inside input angles below 60 degrees). Input\n"
    "vertices come back bit-identical; mesh vertices on input segments lie on them exactly.\n"
    "\n"
    "  -o PREFIX       write PREFIX.node (with boundary markers when the input has them)\n"
    "                  and PREFIX.ele (component id, then the regional attribute if any):\n"
    "                  -o out/m writes out/m.node and out/m.ele (the directory must exist;\n"
    "                  every output is checked writable before any work)\n"
    "  --book          insist on the book's mode (integer vertices in [0,U]^2)\n"
    "  --dyadic        insist on the dyadic-lattice mode\n"
    "  --general       insist on the general mode\n"
    "  --size U        domain side for the book's mode, a power of two (default: the\n"
    "                  smallest power of two >= every coordinate)\n"
    "  --max-size H    longest triangle edge, in input units (guaranteed)\n"
    "  --min-angle DEG the smallest angle wanted (general mode: 20 is the proven default,\n"
    "                  up to 34 is tried without proof; other modes: at most 45); prints\n"
    "                  the bound that applies on stderr\n"
    "  --round G       round every input coordinate to the nearest multiple of G (2^-q or\n"
    "                  a number) before anything else; --stats says how many changed\n"
    "  --round auto    choose G = 2^k from the input (after --project): the finest grid\n"
    "                  on which every segment has exact split points at steps of G\n"
    "                  (2k >= M + W - 52 for coordinates below 2^M and extent below 2^W),\n"
    "                  so a vertex moves at most G/2, about 2^-26 of the extent; stderr\n"
    "                  says the grid. Distinct points that round to one are refused\n"
    "  --project equirect\n"
    "                  GeoJSON lon/lat in degrees: project equirectangularly at the mean\n"
    "                  latitude, in metres (use --round after it: --round auto, or e.g.\n"
    "                  --round 2^-4)\n"
    "  --feature N     GeoJSON: mesh only feature N (0-based, in file order; default: all)\n"
    "  --field NAME=VALUE\n"
    "                  GeoJSON: mesh the first feature whose property NAME is VALUE (as\n"
    "                  join prints it: null reads as empty); stderr says when others match\n"
    "  --poly FILE     the mesh edges along input segments, with markers (.poly)\n"
    "  --svg FILE      picture of the components, quadtree leaves and triangles (the general\n"
    "                  mode grades a quadtree only when its work needs one)\n"
    "  --msh FILE      gmsh 4.1 ASCII mesh: a physical group per component, per region\n"
    "                  (regional attribute) and per marker\n"
    "  --vtk FILE      VTK XML unstructured grid (.vtu): component, region, attribute,\n"
    "                  marker\n"
    "  --stats         print figures as one JSON object on stdout (with the angle\n"
    "                  histogram in 1-degree bins)\n"
    "  IN may be '-' for a .poly on standard input; a name ending in .geojson or .json\n"
    "  (any case) is read as GeoJSON (rings become closed chains, holes get hole points).\n"
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
  const char *in, *prefix, *svg, *msh, *vtk, *poly, *round_text;
  unsigned long size;
  double max_size, min_angle, round; /* round: the grid, or MG_ROUND_AUTO */
  qk_mesh_mode_t mode;
  int stats, help, geojson, project;
  long feature;
  const char *field; /* NAME=VALUE (points into argv) */
  const char *field_value;
} mesh_args_t;

/* --round G: "2^-q", "2^q", a positive number, or "auto" (MG_ROUND_AUTO). */
static int parse_round(const char *cmd, const char *v, double *out) {
  char *end;
  double g;
  if (!strcmp(v, "auto")) {
    *out = MG_ROUND_AUTO;
    return 0;
  }
  if (!strncmp(v, "2^", 2)) {
    long q = strtol(v + 2, &end, 10);
    if (end == v + 2 || *end) {
      cli_error(cmd, "--round %s: expected 2^-q with an integer q, a positive number or auto", v);
      return 1;
    }
    /* (2^-2000 was "expected 2^-q with an integer q", and 2^-1000 "must be a positive
     * number": both are; they are below the smallest step taken, 1e-300.) */
    if (q < -996 || q > 1000) {
      cli_error(cmd,
                "--round %s: the exponent must be from -996 to 1000 (the grid step from "
                "about 1e-300 to 1e301)",
                v);
      return 1;
    }
    g = ldexp(1, (int)q);
  } else {
    if (cli_number(v, &g) != 1) g = -1; /* (decimal only, as every number the tool reads) */
  }
  if (!(g > 0) || !isfinite(g)) {
    cli_error(cmd,
              "--round %s: the grid step must be a positive number (e.g. 2^-4 or 0.5), or auto", v);
    return 1;
  }
  if (g < 1e-300) {
    cli_error(cmd, "--round %s: the grid step must be at least 1e-300", v);
    return 1;
  }
  *out = g;
  return 0;
}

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
    /* (0, the library's "the default", would be read as "no bound" and give 20) */
    if (!(o->min_angle > 0 && o->min_angle <= 45)) {
      cli_error(cmd,
                "--min-angle %s: must be above 0 and at most 45 degrees (the book's and dyadic "
                "modes prove 45; the general mode proves 20, its default, and tries up to 34)",
                v);
      return CLI_USAGE;
    }
  }
  if (!strcmp(a, "--round")) {
    if (parse_round(cmd, v, &o->round)) return CLI_USAGE;
    o->round_text = v;
  }
  if (!strcmp(a, "--project")) {
    if (strcmp(v, "equirect")) {
      cli_error(cmd, "--project %s: the one projection is 'equirect'", v);
      return CLI_USAGE;
    }
    o->project = 1;
  }
  if (!strcmp(a, "--feature")) {
    unsigned long f;
    if (cli_parse_u32(cmd, "--feature", v, 0, 0xfffffffful, &f)) return CLI_USAGE;
    o->feature = (long)f;
  }
  if (!strcmp(a, "--field")) {
    const char *eq = strchr(v, '=');
    if (!eq || eq == v) {
      cli_error(cmd, "--field %s: expected NAME=VALUE", v);
      return CLI_USAGE;
    }
    o->field = v;
    o->field_value = eq + 1;
  }
  return CLI_OK;
}

/* Two outputs naming one file would overwrite each other (the file ending up with
 * whichever was renamed last, or half of each): a usage error, found before any work. */
static int same_file(const char *a, const char *b) {
  struct stat sa, sb;
  if (!strcmp(a, b)) return 1;
  return !stat(a, &sa) && !stat(b, &sb) && sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

static int distinct_outputs(const char *cmd, const mesh_args_t *o) {
  size_t plen = strlen(o->prefix);
  char *node = malloc(plen + 6), *ele = malloc(plen + 5);
  if (!node || !ele) {
    free(node), free(ele);
    cli_error(cmd, "out of memory");
    return CLI_INTERNAL;
  }
  memcpy(node, o->prefix, plen), memcpy(node + plen, ".node", 6);
  memcpy(ele, o->prefix, plen), memcpy(ele + plen, ".ele", 5);
  const char *path[6] = {node, ele, o->svg, o->msh, o->vtk, o->poly};
  static const char *const what[6] = {
      "-o PREFIX (.node)", "-o PREFIX (.ele)", "--svg", "--msh", "--vtk", "--poly"};
  int rc = CLI_OK;
  for (int i = 0; i < 6 && !rc; i++)
    for (int k = i + 1; k < 6 && !rc && path[i]; k++)
      if (path[k] && same_file(path[i], path[k])) {
        cli_error(cmd, "%s and %s both write %s", what[i], what[k], path[k]);
        rc = CLI_USAGE;
      }
  free(node), free(ele);
  return rc;
}

/* The files PREFIX.node and PREFIX.ele are made beside PREFIX. When PREFIX is a device,
 * FIFO or socket, or lies in /dev, they would be regular files in the device directory:
 * `-o /dev/full` (meant as "write nowhere", or to test a full disk) left /dev/full.node
 * and /dev/full.ele there. Refused as a usage error before any work (/dev/shm, a
 * directory for files, is not /dev). */
static int prefix_place(const char *cmd, const char *prefix) {
  struct stat st;
  const char *kind = NULL;
  if (stat(prefix, &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode))
    kind = S_ISCHR(st.st_mode)    ? "a character device"
           : S_ISBLK(st.st_mode)  ? "a block device"
           : S_ISFIFO(st.st_mode) ? "a FIFO"
                                  : "not a regular file";
  const char *slash = strrchr(prefix, '/');
  size_t dlen = slash ? (slash == prefix ? 1 : (size_t)(slash - prefix)) : 1;
  char *dir = malloc(dlen + 1);
  if (!dir) {
    cli_error(cmd, "out of memory");
    return CLI_INTERNAL;
  }
  memcpy(dir, slash ? prefix : ".", dlen);
  dir[dlen] = '\0';
  char *real = realpath(dir, NULL);
  free(dir);
  int in_dev = real && !strcmp(real, "/dev");
  free(real);
  if (!kind && !in_dev) return CLI_OK;
  cli_error(cmd,
            "-o PREFIX names the files PREFIX.node and PREFIX.ele, made beside it: '%s' is %s, "
            "where they must not be made (e.g. -o out/mesh)",
            prefix, kind ? kind : "in /dev");
  return CLI_USAGE;
}

static int parse_args(const char *cmd, int argc, char **argv, mesh_args_t *o) {
  memset(o, 0, sizeof *o);
  o->min_angle = -1;
  o->feature = -1;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
      o->help = 1;
      return CLI_OK;
    }
    static const char *valued[] = {"-o",      "--svg",     "--msh",      "--vtk",
                                   "--poly",  "--size",    "--max-size", "--min-angle",
                                   "--round", "--project", "--feature",  "--field"};
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
    } else if (!strcmp(a, "--book") || !strcmp(a, "--dyadic") || !strcmp(a, "--general")) {
      qk_mesh_mode_t md = a[2] == 'b'   ? QK_MESH_BOOK
                          : a[2] == 'd' ? QK_MESH_DYADIC
                                        : QK_MESH_GENERAL;
      if (o->mode && o->mode != md)
        return usage(cmd, "--book, --dyadic and --general exclude each other");
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
  size_t plen = strlen(o->prefix);
  if (!plen || o->prefix[plen - 1] == '/') { /* (it wrote DIR/.node and DIR/.ele) */
    cli_error(cmd,
              "-o PREFIX names the files PREFIX.node and PREFIX.ele, so it needs a file "
              "name: '%s' %s (e.g. -o out/mesh)",
              o->prefix, plen ? "ends in '/'" : "is empty");
    return CLI_USAGE;
  }
  int place = prefix_place(cmd, o->prefix);
  if (place) return place;
  if ((o->mode == QK_MESH_DYADIC || o->mode == QK_MESH_GENERAL) && o->size)
    return usage(cmd, "--size is the book's domain; the other modes use the input's extent");
  /* (the suffix in any case, as the region reader takes it: "x.GeoJSON" was read as .poly) */
  const char *dot = strrchr(o->in, '.');
  char ext[9] = ""; /* (up to 8 characters after the last dot, lower-cased) */
  for (size_t i = 0; dot && dot[i + 1] && i < 8; i++)
    ext[i] = (char)tolower((unsigned char)dot[i + 1]);
  o->geojson = dot && !strchr(dot, '/') && (!strcmp(ext, "geojson") || !strcmp(ext, "json"));
  if (!o->geojson && (o->project || o->feature >= 0 || o->field))
    return usage(cmd, "--project, --feature and --field apply to GeoJSON input");
  if (o->feature >= 0 && o->field) return usage(cmd, "--feature and --field exclude each other");
  return distinct_outputs(cmd, o);
}

/* The outputs, each through a temporary file renamed only when all were written, so a
 * failure leaves nothing behind. They are opened before any work, so that a path that
 * cannot be written (a missing or read-only directory) is named at once, not after a
 * long meshing run. */
typedef struct outputs {
  char *node_path, *ele_path;
  struct {
    const char *path;
    writer_fn fn;
    cli_out_t out;
  } f[6];
  int opened;
} outputs_t;

/* Close every opened output: renamed into place when ok, else removed. */
static int close_outputs(const char *cmd, outputs_t *w, int ok) {
  int rc = CLI_OK;
  /* Every output flushed before any is renamed into place: a write that fails only when
   * its buffer goes out (a full disk, --msh /dev/full) left the outputs closed before it
   * in place (PREFIX.node and .ele of a command that failed). That output says why. */
  for (int k = 0; ok && k < w->opened; k++)
    if (w->f[k].path && w->f[k].out.f && (fflush(w->f[k].out.f) != 0 || ferror(w->f[k].out.f)))
      ok = 0;
  for (int k = 0; k < w->opened; k++) {
    if (!w->f[k].path || !w->f[k].out.f) continue;
    int c = cli_out_close(cmd, &w->f[k].out, ok && rc == CLI_OK);
    if (rc == CLI_OK) rc = c;
  }
  free(w->node_path);
  free(w->ele_path);
  memset(w, 0, sizeof *w);
  return rc;
}

static int open_outputs(const char *cmd, const mesh_args_t *o, outputs_t *w) {
  memset(w, 0, sizeof *w);
  size_t plen = strlen(o->prefix);
  w->node_path = malloc(plen + 6);
  w->ele_path = malloc(plen + 5);
  if (!w->node_path || !w->ele_path) {
    cli_error(cmd, "out of memory");
    close_outputs(cmd, w, 0);
    return CLI_INTERNAL;
  }
  memcpy(w->node_path, o->prefix, plen);
  memcpy(w->node_path + plen, ".node", 6);
  memcpy(w->ele_path, o->prefix, plen);
  memcpy(w->ele_path + plen, ".ele", 5);
  const char *path[6] = {w->node_path, w->ele_path, o->svg, o->msh, o->vtk, o->poly};
  static const writer_fn fn[6] = {w_node, w_ele, w_svg, w_msh, w_vtu, w_poly};
  for (int k = 0; k < 6; k++) {
    w->f[k].path = path[k];
    w->f[k].fn = fn[k];
    if (!path[k]) continue;
    int rc = cli_out_open(cmd, path[k], &w->f[k].out);
    if (rc != CLI_OK) {
      close_outputs(cmd, w, 0);
      return rc;
    }
    w->opened = k + 1;
  }
  return CLI_OK;
}

/* Write the mesh into every output and flush them (close_outputs renames them into place,
 * once standard output, which --stats writes, is out too). */
static int write_outputs(const char *cmd, outputs_t *w, const qk_mesh_t *mesh, unsigned first) {
  int rc = CLI_OK;
  for (int k = 0; k < w->opened && rc == CLI_OK; k++) {
    if (!w->f[k].path) continue;
    qk_status_t ws = w->f[k].fn(mesh, w->f[k].out.f, first);
    if (ws == QK_OK && (fflush(w->f[k].out.f) != 0 || ferror(w->f[k].out.f))) ws = QK_ERR_IO;
    /* A failed write is said once, with its reason, when the output is closed (it was
     * also "FILE: input/output error" here). */
    if (ws == QK_ERR_IO && ferror(w->f[k].out.f))
      rc = CLI_INTERNAL;
    else if (ws != QK_OK)
      rc = cli_status(cmd, w->f[k].path, ws);
  }
  return rc;
}

/* What the input went through before meshing (for --stats and messages). */
typedef struct prep {
  const char *format;
  size_t rounded, merged, dropped_rings, dup_segments, split_points, filled_holes, gap_faces,
      features;
  double lat0;
  double round;                        /* the grid rounded to (0: none) */
  int round_exp, round_mag, round_ext; /* --round auto: 2^round_exp, and why (mg_auto_grid) */
  int own_exp; /* the coarsest grid 2^own_exp that every coordinate lies on (poly_auto_grid) */
  int merges;  /* rounding to 2^round_exp would make vertices merge_a and merge_b one */
  size_t merge_a, merge_b;
  char name[128];
  mg_input_t gj; /* GeoJSON input (for naming segments in messages) */
} prep_t;

/* The mesher's input from the GeoJSON rings read (their vertices, segments and holes). */
static qk_status_t gj_poly(const prep_t *pp, qk_poly_t **poly, qk_mesh_error_t *err) {
  const mg_input_t *g = &pp->gj;
  return qk_poly_from_arrays(g->xy, g->nv, g->seg, g->ns, g->holes, g->nh, NULL, poly, err);
}

static const char *mode_name(qk_mesh_mode_t m) {
  return m == QK_MESH_BOOK ? "book" : m == QK_MESH_DYADIC ? "dyadic" : "general";
}

/* A JSON string body: quotes and backslashes escaped, control characters dropped. */
static void json_text(const char *s) {
  for (; *s; s++) {
    if (*s == '"' || *s == '\\') putchar('\\');
    if ((unsigned char)*s >= 0x20) putchar(*s);
  }
}

static void print_stats(const qk_mesh_t *mesh, const qk_mesh_stats_t *st, const mesh_args_t *o,
                        const prep_t *pp, double t_read, double t_write) {
  const qk_mesh_stats_t s = *st;
  /* The domain side U, the uniform grid's 2 U^2 triangles and a separate balancing step
   * belong to the lattice modes; the general mode has none of them (its stats say U = 1
   * and a balance time of 0), so they are left out there rather than printed as figures
   * that mean nothing (docs/mesh.md, "--stats"). */
  int lattice = s.mode != QK_MESH_GENERAL;
  putchar('{');
  if (lattice) printf("\"U\": %llu, ", (unsigned long long)s.size);
  printf("\"components\": %zu, \"leaves_before_balance\": %zu, \"leaves\": %zu, "
         "\"triangles\": %zu, \"vertices\": %zu, \"steiner\": %zu, \"min_angle_deg\": %.10g, "
         "\"max_angle_deg\": %.10g, ",
         s.components, s.leaves_before_balance, s.leaves, s.triangles, s.vertices, s.steiner,
         s.min_angle_deg, s.max_angle_deg);
  if (lattice) printf("\"uniform_triangles\": %.0f, ", s.uniform_triangles);
  printf("\"seconds\": {\"read\": %.6f, \"validate\": %.6f, \"subdivide\": %.6f, ", t_read,
         s.seconds_validate, s.seconds_subdivide);
  if (lattice) printf("\"balance\": %.6f, ", s.seconds_balance);
  printf("\"triangulate\": %.6f, \"write\": %.6f}, ", s.seconds_triangulate, t_write);
  printf("\"input\": {\"format\": \"%s\", ", pp->format);
  if (pp->features) {
    printf("\"features\": %zu, \"name\": \"", pp->features);
    json_text(pp->name);
    printf("\", \"projection\": \"%s\", ", o->project ? "equirect" : "none");
    if (o->project) printf("\"lat0_deg\": %.10g, ", pp->lat0);
    printf("\"merged_vertices\": %zu, \"dropped_rings\": %zu, \"duplicate_segments\": %zu, "
           "\"split_points\": %zu, \"filled_holes\": %zu, \"gap_faces\": %zu, ",
           pp->merged, pp->dropped_rings, pp->dup_segments, pp->split_points, pp->filled_holes,
           pp->gap_faces);
  }
  printf("\"round\": %.17g, \"rounded_coordinates\": %zu}, ", pp->round, pp->rounded);
  printf("\"mode\": \"%s\", \"lattice_exponent\": %d, \"origin\": [%.17g, %.17g], "
         "\"proven_min_angle_deg\": %g, \"proven_max_angle_deg\": %g, ",
         mode_name(s.mode), s.lattice_exponent, s.origin_x, s.origin_y, s.proven_min_angle_deg,
         s.proven_max_angle_deg);
  if (s.mode == QK_MESH_GENERAL)
    printf("\"exempt_angles\": %zu, \"smallest_input_angle_deg\": %.10g, "
           "\"split_vertices\": %zu, \"merged_segments\": %zu, ",
           s.exempt_angles, s.smallest_input_angle_deg, s.split_vertices, s.merged_segments);
  printf("\"angle_histogram\": [");
  uint64_t bins[180] = {0};
  if (qk_mesh_angle_histogram(mesh, bins) != QK_OK) memset(bins, 0, sizeof bins); /* (a mesh) */
  for (int k = 0; k < 180; k++) printf("%s%llu", k ? ", " : "", (unsigned long long)bins[k]);
  printf("]}\n");
}

/* Which angle bound applies, on stderr (--min-angle). */
static void report_bound(const qk_mesh_stats_t *st, double asked) {
  const qk_mesh_stats_t s = *st;
  if (s.mode != QK_MESH_GENERAL) {
    fprintf(stderr,
            "quadkit mesh: %s mode: every angle in [%g, %g] degrees (proven; --min-angle %g "
            "met everywhere, small input angles included: the input has none below 45)\n",
            s.mode == QK_MESH_BOOK ? "book's" : "dyadic", s.proven_min_angle_deg,
            s.proven_max_angle_deg, asked);
    return;
  }
  if (s.proven_min_angle_deg > 0)
    fprintf(stderr,
            "quadkit mesh: general mode: every angle >= %g degrees (proven; --min-angle %g) "
            "and <= %g degrees, except %zu angles inside input angles below 60 degrees (the "
            "smallest input angle is %.6g degrees); smallest angle in this mesh %.6g\n",
            s.proven_min_angle_deg, asked, s.proven_max_angle_deg, s.exempt_angles,
            s.smallest_input_angle_deg, s.min_angle_deg);
  else
    fprintf(stderr,
            "quadkit mesh: general mode: --min-angle %g is above the proven bound (20 "
            "degrees): the refinement met it outside input angles below 60 degrees, but no "
            "bound is proven; %zu exempt angles (smallest input angle %.6g degrees); "
            "smallest angle in this mesh %.6g\n",
            asked, s.exempt_angles, s.smallest_input_angle_deg, s.min_angle_deg);
}

/* Append to a mesher's message what its "segment N" is in the GeoJSON input (feature,
 * polygon, ring and position, and that position's line and column in the file), and put
 * in place "FILE:LINE:COL" of the first such position, or "FILE". */
static void name_segment(const prep_t *pp, const char *file, const char *msg, char *buf, size_t n,
                         char *place, size_t np) {
  /* "segment N ...", or "segments N and M ..." (crossing segments: both named) */
  const char *at = strstr(msg, "segment ");
  size_t skip = 8;
  if (!at && (at = strstr(msg, "segments "))) skip = 9;
  char where[160] = "", where2[160] = "";
  unsigned long l1 = 0, c1 = 0, l2 = 0, c2 = 0;
  snprintf(place, np, "%s", file);
  if (at && pp->gj.ns) {
    char *end;
    unsigned long s = strtoul(at + skip, &end, 10);
    if (end == at + skip || s >= pp->gj.ns) {
      snprintf(buf, n, "%s", msg);
      return;
    }
    mg_describe_segment(&pp->gj, file, s, where, sizeof where, &l1, &c1);
    if (skip == 9 && !strncmp(end, " and ", 5)) {
      char *end2;
      unsigned long s2 = strtoul(end + 5, &end2, 10);
      if (end2 != end + 5 && s2 < pp->gj.ns)
        mg_describe_segment(&pp->gj, file, s2, where2, sizeof where2, &l2, &c2);
    }
  }
  if (l1) snprintf(place, np, "%s:%lu:%lu", file, l1, c1);
  if (where[0] && where2[0] && l2)
    snprintf(buf, n, "%s (input segments %s and %s, at %lu:%lu)", msg, where, where2, l2, c2);
  else if (where[0] && where2[0])
    snprintf(buf, n, "%s (input segments %s and %s)", msg, where, where2);
  else if (where[0])
    snprintf(buf, n, "%s (input segment %s)", msg, where);
  else
    snprintf(buf, n, "%s", msg);
}

/* --round auto's grid exponent for the vertices of p (mg_auto_grid), with M and W in pp;
 * returns 0, or 1 out of memory. */
/* A vertex rounded to a grid, with its number, ordered by the rounded point. */
typedef struct rv {
  double x, y;
  size_t i;
} rv_t;

static int rv_cmp(const void *a, const void *b) {
  const rv_t *u = a, *v = b;
  return u->x < v->x ? -1 : u->x > v->x ? 1 : u->y < v->y ? -1 : u->y > v->y ? 1 : 0;
}

/* Whether rounding the nv points xy to 2^e makes two distinct ones coincide (the first
 * such pair, by rounded point, in *a < *b); -1 when out of memory. */
static int grid_merges(const double *xy, size_t nv, int e, size_t *a, size_t *b) {
  rv_t *r = malloc((nv ? nv : 1) * sizeof *r);
  if (!r) return -1;
  for (size_t i = 0; i < nv; i++)
    r[i] = (rv_t){ldexp(nearbyint(ldexp(xy[2 * i], -e)), e),
                  ldexp(nearbyint(ldexp(xy[2 * i + 1], -e)), e), i};
  qsort(r, nv, sizeof *r, rv_cmp);
  int found = 0;
  for (size_t k = 1; k < nv && !found; k++)
    if (r[k].x == r[k - 1].x && r[k].y == r[k - 1].y &&
        (xy[2 * r[k].i] != xy[2 * r[k - 1].i] || xy[2 * r[k].i + 1] != xy[2 * r[k - 1].i + 1])) {
      found = 1;
      *a = r[k].i < r[k - 1].i ? r[k].i : r[k - 1].i;
      *b = r[k].i < r[k - 1].i ? r[k - 1].i : r[k].i;
    }
  free(r);
  return found;
}

/* Whether rounding p's vertices to 2^e would make two distinct ones one: 1 with the two
 * (x, y pairs, in input order) in at[0..3]; 0 when not or out of memory. By coordinates,
 * which name them in a GeoJSON input too (whose vertex numbers the user never sees). */
static int merged_by_grid(const qk_poly_t *p, int e, double at[4]) {
  size_t nv = 0, a = 0, b = 0;
  qk_poly_counts(p, &nv, NULL, NULL);
  double *xy = malloc((nv ? nv : 1) * 2 * sizeof *xy);
  if (!xy) return 0;
  if (qk_poly_vertices(p, xy, nv, &nv) != QK_OK) nv = 0;
  int found = grid_merges(xy, nv, e, &a, &b) > 0;
  if (found) at[0] = xy[2 * a], at[1] = xy[2 * a + 1], at[2] = xy[2 * b], at[3] = xy[2 * b + 1];
  free(xy);
  return found;
}

static int poly_auto_grid(const qk_poly_t *p, prep_t *pp) {
  size_t nv = 0;
  qk_poly_counts(p, &nv, NULL, NULL);
  double *xy = malloc((nv ? nv : 1) * 2 * sizeof *xy);
  if (!xy) return 1;
  if (qk_poly_vertices(p, xy, nv, &nv) != QK_OK) nv = 0; /* (cannot fail: p and room) */
  pp->round_exp = mg_auto_grid(xy, nv, &pp->round_mag, &pp->round_ext);
  /* v = m 2^e with 2^52 <= m < 2^53 a whole number: v lies on the grid 2^(e + ctz(m)). */
  pp->own_exp = INT_MAX;
  for (size_t i = 0; i < 2 * nv; i++) {
    if (xy[i] == 0) continue;
    int e;
    const uint64_t m = (uint64_t)ldexp(fabs(frexp(xy[i], &e)), 53);
    int g = e - 53;
    for (uint64_t b = m; !(b & 1); b >>= 1) g++;
    if (g < pp->own_exp) pp->own_exp = g;
  }
  free(xy);
  return 0;
}

/* The stderr note of --round auto: the grid, why, and how much moved. */
static void auto_note(const char *in, int projected, const prep_t *pp) {
  cli_msg("quadkit mesh: --round auto: the grid 2^%d (coordinates%s below 2^%d, extent below "
          "2^%d): %zu coordinates of %s moved to it, each by at most 2^%d\n",
          pp->round_exp, projected ? " in metres" : "", pp->round_mag, pp->round_ext, pp->rounded,
          in, pp->round_exp - 1);
}

/* Read (and prepare) the input; on failure prints why and returns an exit code. */
static int read_input(const char *cmd, const mesh_args_t *o, qk_poly_t **poly, prep_t *pp) {
  qk_mesh_error_t err;
  memset(&err, 0, sizeof err);
  if (o->geojson) {
    char name[256] = "", msg[2048];
    mg_options_t mo = {o->feature, NULL, NULL, o->project, o->round};
    if (o->field) {
      size_t k = (size_t)(o->field_value - 1 - o->field);
      snprintf(name, sizeof name, "%.*s", (int)(k < sizeof name ? k : sizeof name - 1), o->field);
      mo.field_name = name, mo.field_value = o->field_value;
    }
    int rc = mg_read(o->in, &mo, &pp->gj, msg, sizeof msg);
    if (rc) {
      cli_error(cmd, "%s", msg);
      return rc == 3 ? CLI_INTERNAL : CLI_BAD_INPUT;
    }
    pp->format = "geojson";
    if (pp->gj.field_matches > 1)
      cli_msg("quadkit mesh: --field %s: %zu features match; meshing the first, feature %ld "
              "(--feature N takes another)\n",
              o->field, pp->gj.field_matches, pp->gj.field_pick);
    pp->rounded = pp->gj.rounded, pp->merged = pp->gj.merged;
    pp->dropped_rings = pp->gj.dropped_rings, pp->dup_segments = pp->gj.dup_segments;
    pp->split_points = pp->gj.split_points, pp->filled_holes = pp->gj.filled_holes;
    pp->features = pp->gj.features, pp->lat0 = pp->gj.lat0;
    pp->round = pp->gj.round, pp->round_exp = pp->gj.round_exp;
    pp->round_mag = pp->gj.round_mag, pp->round_ext = pp->gj.round_ext;
    if (o->round == MG_ROUND_AUTO) auto_note(o->in, o->project, pp);
    snprintf(pp->name, sizeof pp->name, "%s", pp->gj.name);
    qk_status_t st = gj_poly(pp, poly, &err);
    if (st != QK_OK) {
      cli_error(cmd, "%s: %s", o->in, err.message[0] ? err.message : qk_strerror(st));
      return st == QK_ERR_NOMEM ? CLI_INTERNAL : CLI_BAD_INPUT;
    }
    return CLI_OK;
  }
  pp->format = "poly";
  FILE *f = strcmp(o->in, "-") ? cli_open_input(cmd, o->in) : stdin;
  if (!f) return CLI_BAD_INPUT;
  /* GeoJSON under another name (or on stdin) would read as a .poly whose first line is
   * not a count: say what it looks like and how it is read. The first byte, put back. */
  int c0 = getc(f);
  if (c0 != EOF) ungetc(c0, f);
  if (c0 == '{' || c0 == '[') {
    cli_error(cmd,
              "%s: this looks like JSON, but the input is read as a .poly file: GeoJSON is "
              "read from a file whose name ends in .geojson or .json (not from stdin)",
              strcmp(o->in, "-") ? o->in : "<stdin>");
    if (f != stdin) fclose(f);
    return CLI_BAD_INPUT;
  }
  /* The .poly reader takes a line of any length into memory: an endless line from a
   * pipe (or a file without line breaks) grew the process until "out of memory". */
  char *copy = NULL;
  int src = cli_screen_input(cmd, strcmp(o->in, "-") ? o->in : "<stdin>", 0, &f, &copy);
  if (src) {
    if (f != stdin) fclose(f);
    return src;
  }
  qk_status_t st = qk_poly_read(f, NULL, poly, &err);
  if (f != stdin) fclose(f);
  free(copy);
  if (st == QK_OK && o->round != 0) {
    pp->round = o->round;
    if (o->round == MG_ROUND_AUTO) {
      if (poly_auto_grid(*poly, pp)) {
        cli_error(cmd, "out of memory");
        return CLI_INTERNAL;
      }
      pp->round = ldexp(1, pp->round_exp);
    }
    /* In place: errors keep the file's lines and vertex numbers, and markers and regional
     * attributes stay (the input was rebuilt from arrays, which lost all of them: "vertices
     * 0 and 3 coincide" for the file's 1 and 4, on no line). Points that round to one are
     * the mesher's to refuse ("vertices 1 and 4 coincide"), with a note on the grid. */
    st = qk_poly_round(*poly, pp->round, &pp->rounded);
    const char *nm = strcmp(o->in, "-") ? o->in : "<stdin>";
    if (st == QK_OK && o->round == MG_ROUND_AUTO)
      auto_note(nm, 0, pp);
    else if (st == QK_OK)
      cli_msg("quadkit mesh: --round %s: %zu coordinates of %s moved to the grid\n", o->round_text,
              pp->rounded, nm);
    else
      snprintf(err.message, sizeof err.message,
               "--round %s: a rounded coordinate is beyond the largest double", o->round_text),
          err.line = 0;
  }
  if (st == QK_OK) return CLI_OK;
  const char *name = strcmp(o->in, "-") ? o->in : "<stdin>";
  /* Triangle's .node file (vertices only) is not a mesh input: the reader's complaint
   * about a missing segment section does not say so. */
  size_t nl = strlen(name);
  const char *node = st == QK_ERR_PARSE && nl > 5 && !strcmp(name + nl - 5, ".node")
                         ? " (a .node file holds vertices only: mesh reads a .poly file, "
                           "which holds the segments and holes too)"
                         : "";
  if (err.line)
    cli_error(cmd, "%s:%lu: %s%s", name, err.line, err.message, node);
  else
    cli_error(cmd, "%s: %s%s", name, err.message[0] ? err.message : qk_strerror(st), node);
  return (st == QK_ERR_NOMEM || st == QK_ERR_IO) ? CLI_INTERNAL : CLI_BAD_INPUT;
}

/*
 * GeoJSON: faces of the mesh inside none of the rings (a gap that features touching all
 * round it enclose, a ring touching itself round a pocket) are outside the area, but no
 * hole point could be found for them from the rings (mesh_geojson.c: such a face cannot
 * be told from the outside of the map there). Each face's largest triangle's centroid is
 * located; the faces outside every ring get it as a hole point and the input is meshed
 * again. Only where rings share a vertex (no such face otherwise). *again: remeshed.
 */
static qk_status_t drop_gap_faces(prep_t *pp, const qk_mesh_options_t *opt, qk_poly_t **poly,
                                  qk_mesh_t **mesh, qk_mesh_error_t *err, int *again) {
  *again = 0;
  if (!mg_rings_touch(&pp->gj)) return QK_OK;
  size_t nt, nc, nv;
  const uint32_t *tri = qk_mesh_triangles(*mesh, &nt),
                 *comp = qk_mesh_triangle_components(*mesh, &nc);
  const double *v = qk_mesh_vertices(*mesh, &nv);
  uint32_t k = 0;
  for (size_t t = 0; t < nt; t++) k = comp[t] > k ? comp[t] : k;
  size_t *best = malloc((k + 1) * sizeof *best);
  double *area = calloc(k + 1, sizeof *area), *pts = malloc(2 * (k + 1) * sizeof *pts);
  unsigned char *out = malloc(k + 1);
  qk_status_t st = best && area && pts && out ? QK_OK : QK_ERR_NOMEM;
  for (size_t t = 0; !st && t < nt; t++) {
    const double *a = &v[2 * tri[3 * t]], *b = &v[2 * tri[3 * t + 1]], *c = &v[2 * tri[3 * t + 2]];
    double ar = fabs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
    if (ar > area[comp[t]]) area[comp[t]] = ar, best[comp[t]] = t;
  }
  size_t np = 0;
  for (uint32_t f = 1; !st && f <= k; f++) {
    if (!(area[f] > 0)) continue;
    const uint32_t *T = &tri[3 * best[f]];
    pts[2 * np] = (v[2 * T[0]] + v[2 * T[1]] + v[2 * T[2]]) / 3;
    pts[2 * np + 1] = (v[2 * T[0] + 1] + v[2 * T[1] + 1] + v[2 * T[2] + 1]) / 3;
    np++;
  }
  if (!st) mg_outside_rings(&pp->gj, pts, np, out);
  size_t add = 0;
  for (size_t i = 0; !st && i < np; i++) add += out[i];
  double *h = !st && add ? realloc(pp->gj.holes, 2 * (pp->gj.nh + add + 1) * sizeof *h) : NULL;
  if (!st && add && !h) st = QK_ERR_NOMEM;
  if (!st && add) {
    pp->gj.holes = h;
    for (size_t i = 0; i < np; i++)
      if (out[i]) h[2 * pp->gj.nh] = pts[2 * i], h[2 * pp->gj.nh + 1] = pts[2 * i + 1], pp->gj.nh++;
    pp->gap_faces = add;
    qk_poly_free(*poly), *poly = NULL;
    qk_mesh_free(*mesh), *mesh = NULL;
    st = gj_poly(pp, poly, err);
    if (!st) st = qk_mesh_generate(*poly, opt, mesh, err);
    *again = 1;
  }
  free(best), free(area), free(pts), free(out);
  return st;
}

/* Read and mesh; on failure prints FILE:LINE: reason and returns an exit code. */
static int make_mesh(const char *cmd, const mesh_args_t *o, qk_poly_t **poly, qk_mesh_t **mesh,
                     prep_t *pp, double *t_read) {
  *t_read = now();
  int rc = read_input(cmd, o, poly, pp);
  *t_read = now() - *t_read;
  if (rc) return rc;
  qk_mesh_error_t err;
  memset(&err, 0, sizeof err);
  qk_mesh_options_t opt;
  qk_mesh_options_init(&opt);
  opt.size = o->size;
  opt.mode = o->mode;
  /* GeoJSON is real-world data: an axis-parallel ring in metres (a graticule cell, a
   * rectangular county) meets the book's or the dyadic conditions, and those modes
   * refine every boundary down to the lattice step (a 111 km square at 1/16 m: tens of
   * millions of triangles). The general mode unless a mode is insisted on. */
  if (o->geojson && !o->mode) opt.mode = QK_MESH_GENERAL;
  opt.max_size = o->max_size;
  if (o->min_angle >= 0) opt.min_angle_deg = o->min_angle;
  qk_status_t st = qk_mesh_generate(*poly, &opt, mesh, &err);
  int again = 0;
  if (st == QK_OK && o->geojson && opt.mode == QK_MESH_GENERAL) {
    st = drop_gap_faces(pp, &opt, poly, mesh, &err, &again);
    if (st == QK_ERR_NOMEM && !again) {
      cli_error(cmd, "%s: out of memory", o->in);
      return CLI_INTERNAL;
    }
  }
  const char *name = strcmp(o->in, "-") ? o->in : "<stdin>";
  if (st == QK_OK) {
    /* No triangle at all: nothing encloses an area outside the holes (an open chain, a
     * lone segment, a ring whose face is a hole). An empty file would drop the input
     * without a word, so say it and write nothing. */
    size_t nt = 0; /* (the count alone: qk_mesh_stats would measure every angle too) */
    qk_mesh_triangles(*mesh, &nt);
    if (nt > 0) return CLI_OK;
    char note[512];
    cli_error(cmd, "%s: nothing to mesh: no closed ring encloses an area outside the holes%s", name,
              mg_pole_note(&pp->gj, note, sizeof note));
    return CLI_BAD_INPUT;
  }
  char msg[1000], place[1024], note[512], why[600];
  snprintf(why, sizeof why, "%s", err.message[0] ? err.message : qk_strerror(st));
  /* A split point without an exact double (mesh/general_refine.c: "... needs a split point
   * ...; exact ones: ... Round the input to a grid (a coarser one if it was rounded
   * already)"). The library's message is cut at 255 characters, often inside that last
   * sentence, which is said here in full instead, with the option to type: the grid
   * --round auto takes, computed from the input as meshed (projected, and rounded if it
   * was). */
  int auto_given = o->round == MG_ROUND_AUTO, split = 0;
  if (st == QK_ERR_GEOMETRY && strstr(why, "needs a split point")) {
    char *cut = strstr(why, " Round the input to a grid");
    if (cut)
      *cut = '\0';
    else
      strcat(why, "."); /* (cut before that sentence) */
    size_t k = strlen(why);
    prep_t a;
    memset(&a, 0, sizeof a);
    split = 1;
    if (auto_given)
      snprintf(why + k, sizeof why - k,
               " Round the input to a coarser grid than 2^%d, which --round auto chose (e.g. "
               "--round 2^%d)",
               pp->round_exp, pp->round_exp + 2);
    else if (poly_auto_grid(*poly, &a))
      snprintf(why + k, sizeof why - k, " Round the input to a grid (--round auto)");
    else {
      /* --round auto's grid helps only where it moves coordinates: not when the input lies
       * on it or a coarser one already (a coastline projected and rounded to 2^-4 m, whose
       * auto grid is 2^-5); then the hint is a grid coarser than the input's own. */
      const int moves = a.own_exp < a.round_exp;
      const int own_coarser =
          a.own_exp != INT_MAX && (o->round <= 0 || ldexp(1, a.own_exp) > o->round);
      double at[4];
      /* (where the advice is --round auto's grid or one coarser than the grid given, and
       * that grid makes two vertices one, it would only trade this refusal for another) */
      if (!(!moves && own_coarser) && merged_by_grid(*poly, a.round_exp, at))
        snprintf(why + k, sizeof why - k,
                 " Rounding cannot help: --round auto's grid 2^%d would make the vertices at "
                 "(%.17g, %.17g) and (%.17g, %.17g) one",
                 a.round_exp, at[0], at[1], at[2], at[3]);
      else if (o->round > 0 && moves && ldexp(1, a.round_exp) > o->round)
        snprintf(why + k, sizeof why - k,
                 " Round the input to a coarser grid than --round %s (--round auto: 2^%d here)",
                 o->round_text, a.round_exp);
      else if (!moves && own_coarser)
        snprintf(why + k, sizeof why - k,
                 " Round the input to a coarser grid than 2^%d, which its coordinates lie on "
                 "(e.g. --round 2^%d)",
                 a.own_exp, a.own_exp + 2);
      else if (o->round > 0)
        snprintf(why + k, sizeof why - k, " Round the input to a coarser grid than --round %s",
                 o->round_text);
      else
        snprintf(why + k, sizeof why - k, " Round the input to a grid: --round auto (2^%d here)",
                 a.round_exp);
    }
    /* Above the proven bound the refinement may ask for ever finer splits, whatever the
     * grid (at --min-angle 34 each coarser grid asked for a point finer by its factor);
     * not said when the segment has no exact split point at all (rounding is the cure). */
    if (o->min_angle > 20.7 && !strstr(why, "exact ones: none")) {
      k = strlen(why);
      snprintf(why + k, sizeof why - k,
               "; above 20.7 degrees (--min-angle %g) the bound is tried, not proven, and "
               "can need splits finer than any grid: the proven 20 may mesh it",
               o->min_angle);
    }
  }
  name_segment(pp, name, why, msg, sizeof msg, place, sizeof place);
  /* After --round auto, an error may come from the rounding (points that became one, a
   * segment now crossing another): say which grid the coordinates were moved to. */
  if (auto_given && !split && st != QK_ERR_NOMEM) {
    size_t k = strlen(msg);
    snprintf(msg + k, sizeof msg - k,
             " (the coordinates were rounded to the grid 2^%d by --round auto)", pp->round_exp);
  }
  const char *pole = mg_pole_note(&pp->gj, note, sizeof note);
  if (err.line)
    cli_error(cmd, "%s:%lu: %s", name, err.line, msg);
  else if (pp->features == 1 && pp->name[0])
    cli_error(cmd, "%s: feature %s: %s%s", place, pp->name, msg, pole);
  else
    cli_error(cmd, "%s: %s%s", place, msg, pole);
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
  prep_t pp;
  memset(&pp, 0, sizeof pp);
  double t_read = 0;
  outputs_t outs;
  cli_note_input(o.in); /* (an output naming the input, or its pipe, is refused) */
  /* --stats writes standard output: opened as an output too, so that another output
   * there (`--svg -`, `--msh /dev/stdout`) is refused rather than mixed into the JSON. */
  cli_out_t so;
  memset(&so, 0, sizeof so);
  if (o.stats && (rc = cli_out_open(cmd, "-", &so))) return rc;
  rc = open_outputs(cmd, &o, &outs);
  if (rc) {
    cli_out_close(cmd, &so, 0);
    return rc;
  }
  rc = make_mesh(cmd, &o, &poly, &mesh, &pp, &t_read);
  if (rc == CLI_OK) {
    double t_write = now();
    rc = write_outputs(cmd, &outs, mesh, qk_poly_first_index(poly));
    t_write = now() - t_write;
    /* (the stats once: in the general mode they measure every angle) */
    qk_mesh_stats_t s;
    if (rc == CLI_OK && (o.min_angle >= 0 || o.stats)) qk_mesh_stats(mesh, &s);
    if (rc == CLI_OK && o.min_angle >= 0) report_bound(&s, o.min_angle);
    if (rc == CLI_OK && o.stats) print_stats(mesh, &s, &o, &pp, t_read, t_write);
  }
  /* Standard output before the files are renamed into place: when it fails (--stats >
   * /dev/full), no file is left behind. */
  int c = cli_out_close(cmd, &so, rc == CLI_OK);
  if (rc == CLI_OK) rc = c;
  c = close_outputs(cmd, &outs, rc == CLI_OK);
  if (rc == CLI_OK) rc = c;
  qk_mesh_free(mesh);
  qk_poly_free(poly);
  mg_free(&pp.gj);
  return rc;
}
