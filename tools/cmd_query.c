/*
 * Query subcommands: knn, range, radius, locate, collide, raycast and geo. Each reads
 * CSV input, builds one index, answers every query with the library, and writes CSV with
 * a header, sorted as its --help says, distances with %.17g so that they round-trip.
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"

/* ---------------------------------------------------------------------------------- */
/* Shared plumbing                                                                      */

typedef struct qargs {
  const char *cmd;
  const char *files[2];
  int nfiles;
  unsigned long capacity;
  unsigned long k;
  int has_k;
  double r;
  int has_r;
  double max_dist;
  const char *out;
  int boxes;
} qargs_t;

/* Parse the options every query command shares; -k, -r and --boxes only where `allow`
 * names them. Returns -1 to go on, or an exit code (after --help or a usage error). */
static int parse_args(int argc, char **argv, const char *allow, int want_files,
                      void (*usage)(FILE *), qargs_t *a) {
  memset(a, 0, sizeof *a);
  a->cmd = argv[0];
  a->capacity = 16;
  a->max_dist = INFINITY;
  for (int i = 1; i < argc; i++) {
    const char *s = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (!strcmp(s, "--help") || !strcmp(s, "-h")) {
      usage(stdout);
      return CLI_OK;
    } else if (!strcmp(s, "--capacity")) {
      if (cli_parse_u32(a->cmd, s, v, 1, UINT32_MAX, &a->capacity)) return CLI_USAGE;
      i++;
    } else if (!strcmp(s, "-k") && strchr(allow, 'k')) {
      if (cli_parse_u32(a->cmd, s, v, 1, 1000000, &a->k)) return CLI_USAGE;
      a->has_k = 1;
      i++;
    } else if (!strcmp(s, "-r") && strchr(allow, 'r')) {
      if (cli_parse_double(a->cmd, s, v, &a->r)) return CLI_USAGE;
      if (a->r < 0) {
        cli_error(a->cmd, "-r must not be negative, not '%s'", v);
        return CLI_USAGE;
      }
      a->has_r = 1;
      i++;
    } else if (!strcmp(s, "--max-dist") && strchr(allow, 'k')) {
      if (cli_parse_double(a->cmd, s, v, &a->max_dist)) return CLI_USAGE;
      if (a->max_dist < 0) {
        cli_error(a->cmd, "--max-dist must not be negative, not '%s'", v);
        return CLI_USAGE;
      }
      i++;
    } else if (!strcmp(s, "--boxes") && strchr(allow, 'b')) {
      a->boxes = 1;
    } else if (!strcmp(s, "-o")) {
      if (!v) {
        cli_error(a->cmd, "-o needs a file name");
        return CLI_USAGE;
      }
      a->out = v;
      i++;
    } else if (s[0] == '-' && s[1]) {
      cli_error(a->cmd, "unknown option '%s' (see quadkit %s --help)", s, a->cmd);
      return CLI_USAGE;
    } else if (a->nfiles < want_files) {
      a->files[a->nfiles++] = s;
    } else {
      cli_error(a->cmd, "unexpected argument '%s'", s);
      return CLI_USAGE;
    }
  }
  if (a->nfiles < want_files) {
    usage(stderr);
    return CLI_USAGE;
  }
  if (strchr(allow, 'k') && !a->has_k) {
    cli_error(a->cmd, "-k K is required");
    return CLI_USAGE;
  }
  if (strchr(allow, 'r') && !a->has_r) {
    cli_error(a->cmd, "-r R is required");
    return CLI_USAGE;
  }
  return -1;
}

/*
 * The line number of a data row, for error messages: the table keeps rows, not lines,
 * so re-read the file with the same rules (blank lines and a leading header skipped).
 */
static long row_line(const char *path, size_t row) {
  FILE *f = fopen(path, "rb");
  if (!f) return 0;
  char *line = NULL;
  size_t cap = 0, seen = 0;
  long lineno = 0, found = 0;
  int first = 1;
  while (getline(&line, &cap, f) >= 0) {
    lineno++;
    const char *q = line;
    if (lineno == 1 && (unsigned char)q[0] == 0xEF) q += 3;
    while (*q == ' ' || *q == '\t') q++;
    if (!*q || *q == '\n' || *q == '\r') continue;
    if (first) {
      first = 0;
      char *end;
      const char *s = *q == '"' ? q + 1 : q;
      strtod(s, &end);
      if (end == s) continue; /* the header */
    }
    if (seen++ == row) {
      found = lineno;
      break;
    }
  }
  free(line);
  fclose(f);
  return found;
}

/* Report bad data in a row as "FILE:LINE: message". */
static int bad_row(const char *path, size_t row, const char *msg) {
  fprintf(stderr, "quadkit: %s:%ld: %s\n", path, row_line(path, row), msg);
  return CLI_BAD_INPUT;
}

static int open_out(const qargs_t *a, cli_out_t *o) {
  return cli_out_open(a->cmd, a->out ? a->out : "-", o);
}

static int build_tree(const qargs_t *a, const qk_point_t *pts, size_t n, qk_tree_t **t) {
  qk_tree_options_t opt;
  qk_tree_options_init(&opt);
  opt.capacity = (uint32_t)a->capacity;
  return cli_build_tree(a->cmd, a->files[0], pts, n, &opt, t);
}

static int nb_by_id(const void *x, const void *y) {
  const qk_neighbor_t *p = x, *q = y;
  return (p->id > q->id) - (p->id < q->id);
}

static int id_cmp(const void *x, const void *y) {
  qk_id_t p = *(const qk_id_t *)x, q = *(const qk_id_t *)y;
  return (p > q) - (p < q);
}

/* ---------------------------------------------------------------------------------- */
/* knn                                                                                  */

static void knn_usage(FILE *f) {
  fprintf(f, "usage: quadkit knn POINTS.csv QUERIES.csv -k K [--max-dist D] [--capacity C] "
             "[-o FILE]\n"
             "The K nearest points to each query (Euclidean), exact; ties by smaller id.\n"
             "Output: query,rank,point,distance  (rank 1..K, by query then rank)\n"
             "  -k K          neighbours per query (1 to 1000000)\n"
             "  --max-dist D  only points within distance D (fewer than K rows then)\n"
             "  --capacity C  points per leaf of the tree (default 16)\n"
             "  -o FILE       write to FILE instead of standard output\n");
}

int cmd_knn(int argc, char **argv) {
  qargs_t a;
  int rc = parse_args(argc, argv, "k", 2, knn_usage, &a);
  if (rc >= 0) return rc;
  qk_point_t *pts = NULL, *qs = NULL;
  size_t n = 0, nq = 0;
  qk_tree_t *t = NULL;
  qk_neighbor_t *nb = NULL;
  if ((rc = cli_read_points(a.files[0], &pts, &n)) || (rc = cli_read_points(a.files[1], &qs, &nq)))
    goto done;
  if ((rc = build_tree(&a, pts, n, &t))) goto done;
  nb = malloc(a.k * sizeof *nb);
  if (!nb) {
    rc = cli_status(a.cmd, "kNN", QK_ERR_NOMEM);
    goto done;
  }
  cli_out_t o;
  if ((rc = open_out(&a, &o))) goto done;
  fprintf(o.f, "query,rank,point,distance\n");
  int ok = 1;
  for (size_t i = 0; i < nq && ok; i++) {
    size_t m;
    qk_status_t st = qk_query_knn(t, qs[i], a.k, a.max_dist, nb, &m);
    if (st != QK_OK) {
      rc = cli_status(a.cmd, a.files[1], st);
      ok = 0;
      break;
    }
    for (size_t j = 0; j < m; j++)
      fprintf(o.f, "%zu,%zu,%u,%.17g\n", i, j + 1, (unsigned)nb[j].id, nb[j].dist);
  }
  int rc2 = cli_out_close(a.cmd, &o, ok);
  if (!rc) rc = rc2;
done:
  free(nb);
  qk_tree_free(t);
  free(pts);
  free(qs);
  return rc;
}

/* ---------------------------------------------------------------------------------- */
/* range                                                                                */

static void range_usage(FILE *f) {
  fprintf(f, "usage: quadkit range POINTS.csv BOXES.csv [--capacity C] [-o FILE]\n"
             "The points inside each closed box (xmin <= x <= xmax, ymin <= y <= ymax).\n"
             "BOXES.csv: xmin,ymin,xmax,ymax per line.\n"
             "Output: box,point  (by box then point)\n"
             "  --capacity C  points per leaf of the tree (default 16)\n"
             "  -o FILE       write to FILE instead of standard output\n");
}

int cmd_range(int argc, char **argv) {
  qargs_t a;
  int rc = parse_args(argc, argv, "", 2, range_usage, &a);
  if (rc >= 0) return rc;
  qk_point_t *pts = NULL;
  size_t n = 0;
  qk_tree_t *t = NULL;
  qk_id_t *ids = NULL;
  cli_table_t boxes = {0};
  if ((rc = cli_read_points(a.files[0], &pts, &n))) goto done;
  if ((rc = cli_read_csv(a.files[1], 4, 4, &boxes))) goto done;
  for (size_t i = 0; i < boxes.rows; i++) {
    const double *b = boxes.v + 4 * i;
    if (b[0] > b[2] || b[1] > b[3]) {
      rc = bad_row(a.files[1], i, "box has xmin > xmax or ymin > ymax");
      goto done;
    }
  }
  if ((rc = build_tree(&a, pts, n, &t))) goto done;
  ids = malloc(n * sizeof *ids);
  if (!ids) {
    rc = cli_status(a.cmd, "range", QK_ERR_NOMEM);
    goto done;
  }
  cli_out_t o;
  if ((rc = open_out(&a, &o))) goto done;
  fprintf(o.f, "box,point\n");
  for (size_t i = 0; i < boxes.rows; i++) {
    const double *b = boxes.v + 4 * i;
    qk_box_t box = {b[0], b[1], b[2], b[3]};
    size_t m;
    qk_query_range_ids(t, box, ids, n, &m);
    qsort(ids, m, sizeof *ids, id_cmp);
    for (size_t j = 0; j < m; j++) fprintf(o.f, "%zu,%u\n", i, (unsigned)ids[j]);
  }
  rc = cli_out_close(a.cmd, &o, 1);
done:
  free(ids);
  qk_tree_free(t);
  free(pts);
  cli_table_free(&boxes);
  return rc;
}

/* ---------------------------------------------------------------------------------- */
/* radius                                                                               */

static void radius_usage(FILE *f) {
  fprintf(f, "usage: quadkit radius POINTS.csv QUERIES.csv -r R [--capacity C] [-o FILE]\n"
             "The points within distance R of each query (inclusive).\n"
             "Output: query,point,distance  (by query then point)\n"
             "  -r R          the radius, >= 0\n"
             "  --capacity C  points per leaf of the tree (default 16)\n"
             "  -o FILE       write to FILE instead of standard output\n");
}

int cmd_radius(int argc, char **argv) {
  qargs_t a;
  int rc = parse_args(argc, argv, "r", 2, radius_usage, &a);
  if (rc >= 0) return rc;
  qk_point_t *pts = NULL, *qs = NULL;
  size_t n = 0, nq = 0;
  qk_tree_t *t = NULL;
  qk_neighbor_t *nb = NULL;
  if ((rc = cli_read_points(a.files[0], &pts, &n)) || (rc = cli_read_points(a.files[1], &qs, &nq)))
    goto done;
  if ((rc = build_tree(&a, pts, n, &t))) goto done;
  nb = malloc(n * sizeof *nb);
  if (!nb) {
    rc = cli_status(a.cmd, "radius", QK_ERR_NOMEM);
    goto done;
  }
  cli_out_t o;
  if ((rc = open_out(&a, &o))) goto done;
  fprintf(o.f, "query,point,distance\n");
  for (size_t i = 0; i < nq; i++) {
    size_t m;
    qk_query_radius_list(t, qs[i], a.r, nb, n, &m);
    qsort(nb, m, sizeof *nb, nb_by_id);
    for (size_t j = 0; j < m; j++)
      fprintf(o.f, "%zu,%u,%.17g\n", i, (unsigned)nb[j].id, nb[j].dist);
  }
  rc = cli_out_close(a.cmd, &o, 1);
done:
  free(nb);
  qk_tree_free(t);
  free(pts);
  free(qs);
  return rc;
}

/* ---------------------------------------------------------------------------------- */
/* locate                                                                               */

static void locate_usage(FILE *f) {
  fprintf(f, "usage: quadkit locate POINTS.csv QUERIES.csv [--capacity C] [-o FILE]\n"
             "The leaf of the tree over POINTS whose square holds each query location\n"
             "(squares are half-open on their west and south sides, the root's edges "
             "included).\n"
             "Output: query,xmin,ymin,side,depth,count  (one row per query, in order; a query\n"
             "outside the root square gets nan,nan,nan,-1,0)\n"
             "  --capacity C  points per leaf of the tree (default 16)\n"
             "  -o FILE       write to FILE instead of standard output\n");
}

int cmd_locate(int argc, char **argv) {
  qargs_t a;
  int rc = parse_args(argc, argv, "", 2, locate_usage, &a);
  if (rc >= 0) return rc;
  qk_point_t *pts = NULL, *qs = NULL;
  size_t n = 0, nq = 0;
  qk_tree_t *t = NULL;
  if ((rc = cli_read_points(a.files[0], &pts, &n)) || (rc = cli_read_points(a.files[1], &qs, &nq)))
    goto done;
  if ((rc = build_tree(&a, pts, n, &t))) goto done;
  cli_out_t o;
  if ((rc = open_out(&a, &o))) goto done;
  fprintf(o.f, "query,xmin,ymin,side,depth,count\n");
  for (size_t i = 0; i < nq; i++) {
    qk_location_t loc;
    if (qk_query_locate(t, qs[i], &loc) != QK_OK) {
      fprintf(o.f, "%zu,nan,nan,nan,-1,0\n", i);
      continue;
    }
    fprintf(o.f, "%zu,%.17g,%.17g,%.17g,%u,%zu\n", i, loc.square.x, loc.square.y, loc.square.side,
            (unsigned)loc.depth, loc.count);
  }
  rc = cli_out_close(a.cmd, &o, 1);
done:
  qk_tree_free(t);
  free(pts);
  free(qs);
  return rc;
}

/* ---------------------------------------------------------------------------------- */
/* collide and raycast                                                                  */

/* Read discs (x,y,r) or, with --boxes, boxes (xmin,ymin,xmax,ymax) into a collider. */
static int read_items(const qargs_t *a, qk_collider_t **c) {
  cli_table_t tb;
  int cols = a->boxes ? 4 : 3;
  int rc = cli_read_csv(a->files[0], cols, cols, &tb);
  if (rc) return rc;
  if (tb.rows == 0) {
    fprintf(stderr, "quadkit: %s: no data rows\n", a->files[0]);
    cli_table_free(&tb);
    return CLI_BAD_INPUT;
  }
  for (size_t i = 0; i < tb.rows; i++) {
    const double *v = tb.v + (size_t)cols * i;
    if (!a->boxes && v[2] < 0) {
      rc = bad_row(a->files[0], i, "disc radius is negative");
      break;
    }
    if (a->boxes && (v[0] > v[2] || v[1] > v[3])) {
      rc = bad_row(a->files[0], i, "box has xmin > xmax or ymin > ymax");
      break;
    }
  }
  if (!rc) {
    qk_tree_options_t opt;
    qk_tree_options_init(&opt);
    opt.capacity = (uint32_t)a->capacity;
    /* cli_table rows are packed doubles in the field order of qk_disc_t / qk_box_t. */
    qk_disc_t *d = NULL;
    qk_box_t *b = NULL;
    if (a->boxes) {
      b = malloc(tb.rows * sizeof *b);
      for (size_t i = 0; b && i < tb.rows; i++)
        b[i] = (qk_box_t){tb.v[4 * i], tb.v[4 * i + 1], tb.v[4 * i + 2], tb.v[4 * i + 3]};
    } else {
      d = malloc(tb.rows * sizeof *d);
      for (size_t i = 0; d && i < tb.rows; i++)
        d[i] = (qk_disc_t){tb.v[3 * i], tb.v[3 * i + 1], tb.v[3 * i + 2]};
    }
    if (!d && !b)
      rc = cli_status(a->cmd, a->files[0], QK_ERR_NOMEM);
    else
      rc = cli_status(a->cmd, a->files[0],
                      qk_collider_build(d, d ? tb.rows : 0, b, b ? tb.rows : 0, &opt, c));
    free(d);
    free(b);
  }
  cli_table_free(&tb);
  return rc;
}

static void collide_usage(FILE *f) {
  fprintf(f, "usage: quadkit collide DISCS.csv [--boxes] [--capacity C] [-o FILE]\n"
             "Every pair of overlapping discs (x,y,r per line); touching counts. With --boxes\n"
             "the file holds boxes (xmin,ymin,xmax,ymax) instead. Ids are 0-based data rows.\n"
             "Output: a,b  (a < b, sorted by a then b)\n"
             "  --capacity C  items per leaf of the tree (default 16)\n"
             "  -o FILE       write to FILE instead of standard output\n");
}

int cmd_collide(int argc, char **argv) {
  qargs_t a;
  int rc = parse_args(argc, argv, "b", 1, collide_usage, &a);
  if (rc >= 0) return rc;
  qk_collider_t *c = NULL;
  qk_pair_t *pairs = NULL;
  if ((rc = read_items(&a, &c))) return rc;
  size_t np = 0;
  qk_collider_pairs_list(c, NULL, 0, &np);
  pairs = malloc((np ? np : 1) * sizeof *pairs);
  if (!pairs) {
    rc = cli_status(a.cmd, "collide", QK_ERR_NOMEM);
    goto done;
  }
  qk_collider_pairs_list(c, pairs, np, &np);
  cli_out_t o;
  if ((rc = open_out(&a, &o))) goto done;
  fprintf(o.f, "a,b\n");
  for (size_t i = 0; i < np; i++)
    fprintf(o.f, "%u,%u\n", (unsigned)pairs[i].a, (unsigned)pairs[i].b);
  rc = cli_out_close(a.cmd, &o, 1);
done:
  free(pairs);
  qk_collider_free(c);
  return rc;
}

static void raycast_usage(FILE *f) {
  fprintf(f, "usage: quadkit raycast DISCS.csv RAYS.csv [--boxes] [--capacity C] [-o FILE]\n"
             "The first disc hit by each ray origin + t * direction, t >= 0 (t = 0 when the\n"
             "origin is inside a disc; ties by smaller id). RAYS.csv: ox,oy,dx,dy and an\n"
             "optional tmax (a segment from o to o + d has tmax 1). With --boxes the first\n"
             "file holds boxes (xmin,ymin,xmax,ymax).\n"
             "Output: ray,disc,t  (one row per ray; ray,-1,inf when nothing is hit)\n"
             "  --capacity C  items per leaf of the tree (default 16)\n"
             "  -o FILE       write to FILE instead of standard output\n");
}

int cmd_raycast(int argc, char **argv) {
  qargs_t a;
  int rc = parse_args(argc, argv, "b", 2, raycast_usage, &a);
  if (rc >= 0) return rc;
  qk_collider_t *c = NULL;
  cli_table_t rays = {0};
  if ((rc = cli_read_csv(a.files[1], 4, 5, &rays))) return rc;
  for (size_t i = 0; i < rays.rows; i++) {
    double tmax = rays.v[5 * i + 4];
    if (!isnan(tmax) && tmax < 0) {
      rc = bad_row(a.files[1], i, "tmax is negative");
      goto done;
    }
  }
  if ((rc = read_items(&a, &c))) goto done;
  cli_out_t o;
  if ((rc = open_out(&a, &o))) goto done;
  fprintf(o.f, "ray,disc,t\n");
  for (size_t i = 0; i < rays.rows; i++) {
    const double *v = rays.v + 5 * i;
    qk_hit_t h;
    qk_collider_raycast(c, (qk_point_t){v[0], v[1]}, (qk_point_t){v[2], v[3]},
                        isnan(v[4]) ? INFINITY : v[4], &h);
    if (h.id == QK_NONE)
      fprintf(o.f, "%zu,-1,inf\n", i);
    else
      fprintf(o.f, "%zu,%u,%.17g\n", i, (unsigned)h.id, h.t);
  }
  rc = cli_out_close(a.cmd, &o, 1);
done:
  qk_collider_free(c);
  cli_table_free(&rays);
  return rc;
}

/* ---------------------------------------------------------------------------------- */
/* geo                                                                                  */

static void geo_usage(FILE *f) {
  fprintf(f, "usage: quadkit geo knn POINTS.csv QUERIES.csv -k K [--max-dist METRES] [options]\n"
             "       quadkit geo radius POINTS.csv QUERIES.csv -r METRES [options]\n"
             "Geodesic queries on the WGS84 ellipsoid: the first two fields are lon,lat in\n"
             "degrees (latitude within [-90, 90]; any longitude, normalised); distances in\n"
             "metres along the geodesic (GeographicLib's algorithm).\n"
             "Output: knn    query,rank,point,metres  (rank 1..K; ties by smaller id)\n"
             "        radius query,point,metres       (by query then point)\n"
             "  --capacity C  points per leaf of the tree (default 16)\n"
             "  -o FILE       write to FILE instead of standard output\n");
}

/* Latitudes must lie in [-90, 90]: say which line does not. */
static int check_lat(const char *path, const qk_point_t *p, size_t n) {
  for (size_t i = 0; i < n; i++)
    if (p[i].y < -90 || p[i].y > 90) {
      char msg[96];
      snprintf(msg, sizeof msg, "latitude %.17g is outside [-90, 90]", p[i].y);
      return bad_row(path, i, msg);
    }
  return CLI_OK;
}

int cmd_geo(int argc, char **argv) {
  if (argc < 2 || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
    geo_usage(argc < 2 ? stderr : stdout);
    return argc < 2 ? CLI_USAGE : CLI_OK;
  }
  int is_knn = !strcmp(argv[1], "knn");
  if (!is_knn && strcmp(argv[1], "radius")) {
    cli_error("geo", "unknown geo query '%s' (knn or radius)", argv[1]);
    return CLI_USAGE;
  }
  qargs_t a;
  argv[1] = "geo";
  int rc = parse_args(argc - 1, argv + 1, is_knn ? "k" : "r", 2, geo_usage, &a);
  if (rc >= 0) return rc;
  qk_point_t *pts = NULL, *qs = NULL;
  size_t n = 0, nq = 0;
  qk_geo_t *g = NULL;
  qk_neighbor_t *nb = NULL;
  if ((rc = cli_read_points(a.files[0], &pts, &n)) || (rc = cli_read_points(a.files[1], &qs, &nq)))
    goto done;
  if ((rc = check_lat(a.files[0], pts, n)) || (rc = check_lat(a.files[1], qs, nq))) goto done;
  qk_tree_options_t opt;
  qk_tree_options_init(&opt);
  opt.capacity = (uint32_t)a.capacity;
  if ((rc = cli_status(a.cmd, a.files[0], qk_geo_build(pts, n, &opt, &g)))) goto done;
  size_t cap = is_knn ? a.k : n;
  nb = malloc(cap * sizeof *nb);
  if (!nb) {
    rc = cli_status(a.cmd, "geo", QK_ERR_NOMEM);
    goto done;
  }
  cli_out_t o;
  if ((rc = open_out(&a, &o))) goto done;
  fprintf(o.f, is_knn ? "query,rank,point,metres\n" : "query,point,metres\n");
  for (size_t i = 0; i < nq; i++) {
    size_t m;
    if (is_knn) {
      qk_geo_knn(g, qs[i], a.k, a.max_dist, nb, &m);
      for (size_t j = 0; j < m; j++)
        fprintf(o.f, "%zu,%zu,%u,%.17g\n", i, j + 1, (unsigned)nb[j].id, nb[j].dist);
    } else {
      qk_geo_radius_list(g, qs[i], a.r, nb, cap, &m);
      qsort(nb, m, sizeof *nb, nb_by_id);
      for (size_t j = 0; j < m; j++)
        fprintf(o.f, "%zu,%u,%.17g\n", i, (unsigned)nb[j].id, nb[j].dist);
    }
  }
  rc = cli_out_close(a.cmd, &o, 1);
done:
  free(nb);
  qk_geo_free(g);
  free(pts);
  free(qs);
  return rc;
}
