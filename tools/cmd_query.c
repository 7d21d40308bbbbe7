/*
 * Query subcommands: knn, range, radius, locate, collide, raycast and geo. One driver
 * (run_query) parses the shared options, reads the inputs, lets the command build its
 * index, and writes CSV with a header, sorted as each --help says, distances with %.17g
 * so that they round-trip; --keep appends the input rows' own fields. A command is its
 * usage text, its inputs, its output columns and two functions: prepare and answer.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"

/* ---------------------------------------------------------------------------------- */
/* The driver                                                                           */

enum { IN_POINTS = 1, IN_BOXES, IN_ITEMS, IN_RAYS };

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
  const char *xy, *query_xy, *keep;
} qargs_t;

typedef struct qrun qrun_t;

typedef struct qcmd {
  const char *allow;   /* the optional options it takes: k (-k, --max-dist), r, b (--boxes) */
  int nfiles;          /* input files */
  int kind[2];         /* what each holds (IN_*) */
  const char *head;    /* the result columns */
  const char *side[2]; /* the id columns --keep may name (NULL: none) */
  int side_file[2];    /* the input each id column refers to */
  void (*usage)(FILE *);
  int (*prepare)(qrun_t *);
  int (*answer)(qrun_t *, size_t i); /* the rows for item i of the second input */
  const struct qcmd *boxes;          /* the command --boxes turns it into (NULL: itself) */
} qcmd_t;

struct qrun {
  qargs_t a;
  const qcmd_t *c;
  int keep[2];
  cli_rows_t rows[2];
  qk_point_t *pts[2];
  size_t n[2];
  cli_table_t tab[2];
  qk_tree_t *tree;
  qk_geo_t *geo;
  qk_collider_t *col;
  qk_neighbor_t *nb;
  qk_id_t *ids;
  qk_pair_t *pairs;
  qk_hit_t *hits; /* raycast: every ray's answer, found before anything is written */
  size_t cap;
  FILE *f;
};

/* Parse the options every query command shares; -k, -r and --boxes only where `allow`
 * names them. Returns -1 to go on, or an exit code (after --help or a usage error). */
static int parse_args(int argc, char **argv, const qcmd_t *c, qargs_t *a) {
  const char *allow = c->allow;
  memset(a, 0, sizeof *a);
  a->cmd = argv[0];
  a->capacity = 16;
  a->max_dist = INFINITY;
  int points = c->kind[0] == IN_POINTS || c->kind[1] == IN_POINTS;
  for (int i = 1; i < argc; i++) {
    const char *s = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (!strcmp(s, "--help") || !strcmp(s, "-h")) {
      c->usage(stdout);
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
    } else if ((!strcmp(s, "--xy") && points) ||
               (!strcmp(s, "--query-xy") && c->kind[1] == IN_POINTS)) {
      if (cli_parse_xy(a->cmd, s, v, s[2] == 'x' ? &a->xy : &a->query_xy)) return CLI_USAGE;
      i++;
    } else if (!strcmp(s, "--keep")) {
      if (!v) {
        cli_error(a->cmd, "--keep needs a value");
        return CLI_USAGE;
      }
      a->keep = v;
      i++;
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
    } else if (a->nfiles < c->nfiles) {
      a->files[a->nfiles++] = s;
    } else {
      cli_error(a->cmd, "unexpected argument '%s'", s);
      return CLI_USAGE;
    }
  }
  if (a->nfiles < c->nfiles) {
    c->usage(stderr);
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

/* --keep WHICH: the id columns named (comma-separated), or "both" where there are two. Each
 * name is checked, however long the value (it was cut at 63 bytes, and what followed went
 * unchecked), and an empty one is refused ('' and ',' did nothing, exit 0). */
static int parse_keep(qrun_t *q) {
  const char *s = q->a.keep;
  if (!s) return CLI_OK;
  for (const char *t = s;; t++) {
    const char *e = strchr(t, ',');
    size_t n = e ? (size_t)(e - t) : strlen(t);
    int hit = 0;
    for (int k = 0; k < 2 && n; k++) {
      const char *side = q->c->side[k];
      if (side && ((strlen(side) == n && !strncmp(t, side, n)) ||
                   (n == 4 && !strncmp(t, "both", 4) && q->c->side[1])))
        q->keep[k] = hit = 1;
    }
    if (!hit) {
      /* (the name refused, or the whole value when the name is empty; cut at 40 bytes
       * as the readers cut a value) */
      const char *shown = n ? t : s;
      size_t len = n ? n : strlen(s);
      cli_error(q->a.cmd, "--keep takes %s%s%s%s, not '%.*s'%s%s", q->c->side[0],
                q->c->side[1] ? ", " : "", q->c->side[1] ? q->c->side[1] : "",
                q->c->side[1] ? " or both" : "", (int)(len > 40 ? 40 : len), shown,
                len > 40 ? "..." : "", n ? "" : " (an empty name)");
      return CLI_USAGE;
    }
    if (!e) break;
    t = e;
  }
  return CLI_OK;
}

/* Read input i as its kind says (rows' text kept when --keep names it). */
static int read_input(qrun_t *q, int i) {
  const char *path = q->a.files[i];
  for (int k = 0; k < 2; k++)
    if (q->keep[k] && q->c->side_file[k] == i) q->rows[i].keep_text = 1;
  switch (q->c->kind[i]) {
  case IN_POINTS: {
    const char *xy = i == 1 && q->a.query_xy ? q->a.query_xy : q->a.xy;
    return (i == 0 ? cli_read_points : cli_read_queries)(path, xy, &q->rows[i], &q->pts[i],
                                                         &q->n[i]);
  }
  case IN_BOXES:
    return cli_read_table(path, 4, 4, &q->rows[i], &q->tab[i]);
  case IN_ITEMS:
    return cli_read_table(path, q->a.boxes ? 4 : 3, q->a.boxes ? 4 : 3, &q->rows[i], &q->tab[i]);
  default:
    return cli_read_table(path, 4, 5, &q->rows[i], &q->tab[i]);
  }
}

/* Report bad data in row `row` of input i as "FILE:LINE: message". */
static int bad_row(const qrun_t *q, int i, size_t row, const char *msg) {
  cli_msg("quadkit: %s:%lu: %s\n", cli_input_name(q->a.files[i]), q->rows[i].lineno[row], msg);
  return CLI_BAD_INPUT;
}

/* A box (xmin, ymin, xmax, ymax: the first four fields) whose corners are swapped: which
 * pair, with the values (bad_row's message). */
static int bad_box(const qrun_t *q, int i, size_t row, const double *b) {
  char msg[160];
  int y = !(b[0] > b[2]);
  snprintf(msg, sizeof msg,
           "box has xmin > xmax or ymin > ymax: %s %.17g > %s %.17g (fields %d and %d)",
           y ? "ymin" : "xmin", b[y], y ? "ymax" : "xmax", b[2 + y], 1 + y, 3 + y);
  return bad_row(q, i, row, msg);
}

/* One output row: the result columns, then the kept rows of ids a and b (QK_NONE or
 * SIZE_MAX: empty fields). */
static void emit(qrun_t *q, size_t a, size_t b, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vfprintf(q->f, fmt, ap);
  va_end(ap);
  for (int k = 0; k < 2; k++) {
    if (!q->keep[k]) continue;
    const cli_rows_t *r = &q->rows[q->c->side_file[k]];
    size_t id = k ? b : a;
    cli_write_fields(q->f, id < r->n ? r->text[id] : NULL, r->width, NULL);
  }
  fputc('\n', q->f);
}

static void write_head(qrun_t *q) {
  fputs(q->c->head, q->f);
  for (int k = 0; k < 2; k++) {
    if (!q->keep[k]) continue;
    const cli_rows_t *r = &q->rows[q->c->side_file[k]];
    char prefix[32];
    snprintf(prefix, sizeof prefix, "%s_", q->c->side[k]);
    cli_write_fields(q->f, r->header, r->width, prefix);
  }
  fputc('\n', q->f);
}

static void run_free(qrun_t *q) {
  for (int i = 0; i < 2; i++) {
    cli_rows_free(&q->rows[i]);
    free(q->pts[i]);
    cli_table_free(&q->tab[i]);
  }
  qk_tree_free(q->tree);
  qk_geo_free(q->geo);
  qk_collider_free(q->col);
  free(q->nb);
  free(q->ids);
  free(q->pairs);
  free(q->hits);
}

/* Parse, read, prepare, answer every item of the second input (or once), write. */
static int run_query(int argc, char **argv, const qcmd_t *c) {
  qrun_t q;
  memset(&q, 0, sizeof q);
  q.c = c;
  int rc = parse_args(argc, argv, c, &q.a);
  if (rc >= 0) return rc;
  if (q.a.boxes && c->boxes) q.c = c = c->boxes;
  if ((rc = parse_keep(&q))) return rc;
  if ((rc = cli_inputs_once(q.a.cmd, q.a.files, c->nfiles))) return rc;
  /* The output is opened before the inputs are read (they are noted first, so that one
   * naming an input, or its pipe, is still refused): a path that cannot be written fails
   * at once, not after reading, building and answering (2.9 s on 10^6 discs). It is
   * written only once every answer is known to be printable; on an error it is closed
   * unwritten (a file's temporary removed, an existing file unchanged). */
  for (int i = 0; i < c->nfiles; i++) cli_note_input(q.a.files[i]);
  cli_out_t o;
  if ((rc = cli_out_open(q.a.cmd, q.a.out ? q.a.out : "-", &o))) return rc;
  for (int i = 0; i < c->nfiles && !rc; i++) rc = read_input(&q, i);
  if (!rc) rc = c->prepare(&q);
  if (!rc) {
    q.f = o.f;
    write_head(&q);
    size_t items = c->nfiles < 2 ? 1 : c->kind[1] == IN_POINTS ? q.n[1] : q.tab[1].rows;
    for (size_t i = 0; i < items && !rc; i++) rc = c->answer(&q, i);
  }
  int rc2 = cli_out_close(q.a.cmd, &o, rc == CLI_OK);
  if (!rc) rc = rc2;
  run_free(&q);
  return rc;
}

static int build_tree(qrun_t *q) {
  qk_tree_options_t opt;
  qk_tree_options_init(&opt);
  opt.capacity = (uint32_t)q->a.capacity;
  return cli_build_tree(q->a.cmd, cli_input_name(q->a.files[0]), q->pts[0], q->n[0], &opt,
                        &q->tree);
}

/* Scratch for up to `cap` neighbours or ids. */
static int scratch(qrun_t *q, size_t cap, int ids) {
  q->cap = cap;
  if (ids)
    q->ids = malloc((cap ? cap : 1) * sizeof *q->ids);
  else
    q->nb = malloc((cap ? cap : 1) * sizeof *q->nb);
  return (ids ? !!q->ids : !!q->nb) ? CLI_OK : cli_status(q->a.cmd, "scratch", QK_ERR_NOMEM);
}

static int nb_by_id(const void *x, const void *y) {
  const qk_neighbor_t *p = x, *q = y;
  return (p->id > q->id) - (p->id < q->id);
}

static int id_cmp(const void *x, const void *y) {
  qk_id_t p = *(const qk_id_t *)x, q = *(const qk_id_t *)y;
  return (p > q) - (p < q);
}

#define KEEP_HELP(sides)                                                                           \
  "  --keep WHICH  append the input rows' own fields (" sides "), each header\n"                   \
  "                name prefixed with WHICH_\n"
#define XY_HELP                                                                                    \
  "  --xy X,Y      the columns holding x and y: header names or 1-based numbers\n"                 \
  "                (default: the first two)\n"
#define COMMON_HELP                                                                                \
  "  --capacity C  points per leaf of the tree (default 16)\n"                                     \
  "  -o FILE       write to FILE instead of standard output\n"

/* ---------------------------------------------------------------------------------- */
/* knn and radius                                                                       */

static void knn_usage(FILE *f) {
  fprintf(f, "usage: quadkit knn POINTS.csv QUERIES.csv -k K [--max-dist D] [options]\n"
             "The K nearest points to each query (Euclidean), exact; ties by smaller id.\n"
             "Output: query,rank,point,distance  (rank 1..K, by query then rank)\n"
             "  -k K          neighbours per query (1 to 1000000)\n"
             "  --max-dist D  only points within distance D (fewer than K rows then)\n" XY_HELP
             "  --query-xy X,Y  the same for QUERIES.csv only\n" KEEP_HELP("query, point or both")
                 COMMON_HELP);
}

static int knn_beyond(qrun_t *q, size_t i) {
  cli_error(q->a.cmd,
            "%s: query %zu (%.17g, %.17g): the query or the points reach beyond 2^510 "
            "(about 3.4e153) on an axis, where squared distances overflow; scale the data by "
            "a power of two",
            cli_input_name(q->a.files[1]), i, q->pts[1][i].x, q->pts[1][i].y);
  return CLI_BAD_INPUT;
}

/* qk_query_knn's QK_ERR_LIMIT (the query or the root square beyond 2^510 on an axis),
 * found before the header: standard output cannot be taken back. radius too: there
 * squared distances overflow to infinity and compare <= r * r, so points 1.4e300 away
 * were listed within -r 1e300, at distance inf. Within 2^510 every squared distance is
 * finite, and an r whose square overflows is farther than any point. */
static int beyond_check(qrun_t *q) {
  static const char why[] = "beyond 2^510 (about 3.4e153) on an axis, where squared distances "
                            "overflow; scale the data by a power of two";
  char msg[240];
  for (int f = 0; f < 2; f++) /* the points first: a point names its own row */
    for (size_t i = 0; i < q->n[f]; i++)
      if (fmax(fabs(q->pts[f][i].x), fabs(q->pts[f][i].y)) > 0x1p510) {
        snprintf(msg, sizeof msg, "%s (%.17g, %.17g) is %s", f ? "query" : "point", q->pts[f][i].x,
                 q->pts[f][i].y, why);
        return bad_row(q, f, i, msg);
      }
  qk_tree_stats_t s;
  qk_tree_stats(q->tree, &s);
  if (fmax(fmax(fabs(s.root.x), fabs(s.root.y)),
           fmax(fabs(s.root.x + s.root.side), fabs(s.root.y + s.root.side))) > 0x1p510) {
    /* (the points within, their enclosing square not: a point near 2^510) */
    cli_error(q->a.cmd, "%s: the square enclosing the points reaches %s",
              cli_input_name(q->a.files[0]), why);
    return CLI_BAD_INPUT;
  }
  return CLI_OK;
}

static int knn_prepare(qrun_t *q) {
  int rc = build_tree(q);
  if (!rc) rc = beyond_check(q);
  return rc ? rc : scratch(q, q->a.k, 0);
}

static int knn_answer(qrun_t *q, size_t i) {
  size_t m;
  qk_status_t st = qk_query_knn(q->tree, q->pts[1][i], q->a.k, q->a.max_dist, q->nb, &m);
  if (st == QK_ERR_LIMIT) return knn_beyond(q, i);
  if (st != QK_OK) return cli_status(q->a.cmd, cli_input_name(q->a.files[1]), st);
  for (size_t j = 0; j < m; j++)
    emit(q, i, q->nb[j].id, "%zu,%zu,%u,%.17g", i, j + 1, (unsigned)q->nb[j].id, q->nb[j].dist);
  return CLI_OK;
}

static const qcmd_t knn_cmd = {.allow = "k",
                               .nfiles = 2,
                               .kind = {IN_POINTS, IN_POINTS},
                               .head = "query,rank,point,distance",
                               .side = {"query", "point"},
                               .side_file = {1, 0},
                               .usage = knn_usage,
                               .prepare = knn_prepare,
                               .answer = knn_answer};

int cmd_knn(int argc, char **argv) { return run_query(argc, argv, &knn_cmd); }

static void radius_usage(FILE *f) {
  fprintf(f, "usage: quadkit radius POINTS.csv QUERIES.csv -r R [options]\n"
             "The points within distance R of each query (inclusive).\n"
             "Output: query,point,distance  (by query then point)\n"
             "  -r R          the radius, >= 0\n" XY_HELP
             "  --query-xy X,Y  the same for QUERIES.csv only\n" KEEP_HELP("query, point or both")
                 COMMON_HELP);
}

static int radius_prepare(qrun_t *q) {
  int rc = build_tree(q);
  if (!rc) rc = beyond_check(q);
  return rc ? rc : scratch(q, q->n[0], 0);
}

static int radius_answer(qrun_t *q, size_t i) {
  size_t m = 0;
  qk_status_t st = qk_query_radius_list(q->tree, q->pts[1][i], q->a.r, q->nb, q->cap, &m);
  if (st != QK_OK) return cli_status(q->a.cmd, cli_input_name(q->a.files[1]), st);
  qsort(q->nb, m, sizeof *q->nb, nb_by_id);
  for (size_t j = 0; j < m; j++)
    emit(q, i, q->nb[j].id, "%zu,%u,%.17g", i, (unsigned)q->nb[j].id, q->nb[j].dist);
  return CLI_OK;
}

static const qcmd_t radius_cmd = {.allow = "r",
                                  .nfiles = 2,
                                  .kind = {IN_POINTS, IN_POINTS},
                                  .head = "query,point,distance",
                                  .side = {"query", "point"},
                                  .side_file = {1, 0},
                                  .usage = radius_usage,
                                  .prepare = radius_prepare,
                                  .answer = radius_answer};

int cmd_radius(int argc, char **argv) { return run_query(argc, argv, &radius_cmd); }

/* ---------------------------------------------------------------------------------- */
/* range and locate                                                                     */

static void range_usage(FILE *f) {
  fprintf(f, "usage: quadkit range POINTS.csv BOXES.csv [options]\n"
             "The points inside each closed box (xmin <= x <= xmax, ymin <= y <= ymax).\n"
             "BOXES.csv: xmin,ymin,xmax,ymax per line.\n"
             "Output: box,point  (by box then point)\n" XY_HELP KEEP_HELP("box, point or both")
                 COMMON_HELP);
}

static int range_prepare(qrun_t *q) {
  for (size_t i = 0; i < q->tab[1].rows; i++) {
    const double *b = q->tab[1].v + 4 * i;
    if (b[0] > b[2] || b[1] > b[3]) return bad_box(q, 1, i, b);
  }
  int rc = build_tree(q);
  return rc ? rc : scratch(q, q->n[0], 1);
}

static int range_answer(qrun_t *q, size_t i) {
  const double *b = q->tab[1].v + 4 * i;
  size_t m = 0;
  qk_status_t st =
      qk_query_range_ids(q->tree, (qk_box_t){b[0], b[1], b[2], b[3]}, q->ids, q->cap, &m);
  if (st != QK_OK) return cli_status(q->a.cmd, cli_input_name(q->a.files[1]), st);
  qsort(q->ids, m, sizeof *q->ids, id_cmp);
  for (size_t j = 0; j < m; j++) emit(q, i, q->ids[j], "%zu,%u", i, (unsigned)q->ids[j]);
  return CLI_OK;
}

static const qcmd_t range_cmd = {.allow = "",
                                 .nfiles = 2,
                                 .kind = {IN_POINTS, IN_BOXES},
                                 .head = "box,point",
                                 .side = {"box", "point"},
                                 .side_file = {1, 0},
                                 .usage = range_usage,
                                 .prepare = range_prepare,
                                 .answer = range_answer};

int cmd_range(int argc, char **argv) { return run_query(argc, argv, &range_cmd); }

static void locate_usage(FILE *f) {
  fprintf(f, "usage: quadkit locate POINTS.csv QUERIES.csv [options]\n"
             "The leaf of the tree over POINTS whose square holds each query location\n"
             "(squares are half-open on their west and south sides, the root's edges "
             "included).\n"
             "Output: query,xmin,ymin,side,depth,count  (one row per query, in order; a query\n"
             "outside the root square gets nan,nan,nan,-1,0)\n" XY_HELP
             "  --query-xy X,Y  the same for QUERIES.csv only\n" KEEP_HELP("query") COMMON_HELP);
}

static int locate_answer(qrun_t *q, size_t i) {
  qk_location_t loc;
  if (qk_query_locate(q->tree, q->pts[1][i], &loc) != QK_OK)
    emit(q, i, SIZE_MAX, "%zu,nan,nan,nan,-1,0", i);
  else
    emit(q, i, SIZE_MAX, "%zu,%.17g,%.17g,%.17g,%u,%zu", i, loc.square.x + 0.0, loc.square.y + 0.0,
         loc.square.side, (unsigned)loc.depth, loc.count); /* (-0 as 0) */
  return CLI_OK;
}

static const qcmd_t locate_cmd = {.allow = "",
                                  .nfiles = 2,
                                  .kind = {IN_POINTS, IN_POINTS},
                                  .head = "query,xmin,ymin,side,depth,count",
                                  .side = {"query", NULL},
                                  .side_file = {1, 0},
                                  .usage = locate_usage,
                                  .prepare = build_tree,
                                  .answer = locate_answer};

int cmd_locate(int argc, char **argv) { return run_query(argc, argv, &locate_cmd); }

/* ---------------------------------------------------------------------------------- */
/* collide and raycast                                                                  */

/* Check the discs (x,y,r) or boxes (xmin,ymin,xmax,ymax) of input 0; build the collider. */
static int build_collider(qrun_t *q) {
  const cli_table_t *tb = &q->tab[0];
  if (tb->rows == 0) {
    cli_msg("quadkit: %s: no data rows\n", cli_input_name(q->a.files[0]));
    return CLI_BAD_INPUT;
  }
  for (size_t i = 0; i < tb->rows; i++) {
    const double *v = tb->v + (size_t)tb->cols * i;
    if (!q->a.boxes && v[2] < 0) {
      char msg[96];
      snprintf(msg, sizeof msg, "disc radius is negative: %.17g (field 3)", v[2]);
      return bad_row(q, 0, i, msg);
    }
    if (q->a.boxes && (v[0] > v[2] || v[1] > v[3])) return bad_box(q, 0, i, v);
  }
  qk_tree_options_t opt;
  qk_tree_options_init(&opt);
  opt.capacity = (uint32_t)q->a.capacity;
  /* The rows are packed doubles in the field order of qk_disc_t / qk_box_t. */
  qk_disc_t *d = NULL;
  qk_box_t *b = NULL;
  if (q->a.boxes) {
    b = malloc(tb->rows * sizeof *b);
    for (size_t i = 0; b && i < tb->rows; i++)
      b[i] = (qk_box_t){tb->v[4 * i], tb->v[4 * i + 1], tb->v[4 * i + 2], tb->v[4 * i + 3]};
  } else {
    d = malloc(tb->rows * sizeof *d);
    for (size_t i = 0; d && i < tb->rows; i++)
      d[i] = (qk_disc_t){tb->v[3 * i], tb->v[3 * i + 1], tb->v[3 * i + 2]};
  }
  int rc;
  if (!d && !b)
    rc = cli_status(q->a.cmd, cli_input_name(q->a.files[0]), QK_ERR_NOMEM);
  else
    rc = cli_status(q->a.cmd, cli_input_name(q->a.files[0]),
                    qk_collider_build(d, d ? tb->rows : 0, b, b ? tb->rows : 0, &opt, &q->col));
  free(d);
  free(b);
  return rc;
}

static void collide_usage(FILE *f) {
  fprintf(f, "usage: quadkit collide DISCS.csv [--boxes] [options]\n"
             "Every pair of overlapping discs (x,y,r per line); touching counts. With --boxes\n"
             "the file holds boxes (xmin,ymin,xmax,ymax) instead. Ids are 0-based data rows.\n"
             "Output: a,b  (a < b, sorted by a then b)\n" KEEP_HELP(
                 "a, b or both") "  --capacity C  items per leaf of the tree (default 16)\n"
                                 "  -o FILE       write to FILE instead of standard output\n");
}

static int collide_prepare(qrun_t *q) {
  /* Discs overlap when dx^2 + dy^2 <= (r1 + r2)^2 in doubles (qk_collider_build): with
   * values beyond 2^200 the squares overflowed to inf <= inf, and with nonzero values
   * below 2^-200 they underflowed to 0 <= 0, so discs 1.4e300 or 2.8e-170 apart were
   * listed as touching. In [2^-200, 2^200] (or 0) a nonzero difference is at least
   * 2^-252 and no square overflows or underflows. Boxes are only compared. */
  const cli_table_t *tb = &q->tab[0];
  for (size_t i = 0; !q->a.boxes && i < tb->rows; i++)
    for (int k = 0; k < 3; k++) {
      double a = fabs(tb->v[3 * i + (size_t)k]);
      if (a != 0 && (a < 0x1p-200 || a > 0x1p200)) {
        char msg[256];
        snprintf(msg, sizeof msg,
                 "field %d: %.17g is outside [2^-200, 2^200] in magnitude, where the disc "
                 "overlap test's squares overflow or underflow; scale the data by a power of two",
                 k + 1, tb->v[3 * i + (size_t)k]);
        return bad_row(q, 0, i, msg);
      }
    }
  int rc = build_collider(q);
  if (rc) return rc;
  size_t np = 0;
  qk_status_t st = qk_collider_pairs_list(q->col, NULL, 0, &np);
  if (st != QK_OK) return cli_status(q->a.cmd, "collide", st);
  q->pairs = malloc((np ? np : 1) * sizeof *q->pairs);
  if (!q->pairs) return cli_status(q->a.cmd, "collide", QK_ERR_NOMEM);
  st = qk_collider_pairs_list(q->col, q->pairs, np, &q->cap);
  if (st == QK_OK && q->cap != np) st = QK_ERR_CORRUPT;
  return st == QK_OK ? CLI_OK : cli_status(q->a.cmd, "collide", st);
}

static int collide_answer(qrun_t *q, size_t i) {
  (void)i; /* one input: all the pairs at once */
  for (size_t j = 0; j < q->cap; j++)
    emit(q, q->pairs[j].a, q->pairs[j].b, "%u,%u", (unsigned)q->pairs[j].a,
         (unsigned)q->pairs[j].b);
  return CLI_OK;
}

static const qcmd_t collide_cmd = {.allow = "b",
                                   .nfiles = 1,
                                   .kind = {IN_ITEMS, 0},
                                   .head = "a,b",
                                   .side = {"a", "b"},
                                   .side_file = {0, 0},
                                   .usage = collide_usage,
                                   .prepare = collide_prepare,
                                   .answer = collide_answer};

int cmd_collide(int argc, char **argv) { return run_query(argc, argv, &collide_cmd); }

static void raycast_usage(FILE *f) {
  fprintf(f, "usage: quadkit raycast DISCS.csv RAYS.csv [--boxes] [options]\n"
             "The first disc hit by each ray origin + t * direction, t >= 0 (t = 0 when the\n"
             "origin is inside a disc; ties by smaller id). RAYS.csv: ox,oy,dx,dy and an\n"
             "optional tmax (a segment from o to o + d has tmax 1; an empty or missing field\n"
             "means no limit: like every input value it must be finite). A direction of 0,0 is\n"
             "the point at the origin: it hits the lowest-numbered disc that contains or\n"
             "touches it (t = 0), else nothing. With --boxes the first file holds boxes\n"
             "(xmin,ymin,xmax,ymax), and the output and --keep say box for disc (ray,box,t).\n"
             "Output: ray,disc,t  (one row per ray; ray,-1,inf when nothing is hit)\n");
  fputs(KEEP_HELP("ray, disc or both") "  --capacity C  items per leaf of the tree (default 16)\n"
                                       "  -o FILE       write to FILE instead of standard output\n",
        f);
}

/* Every ray is cast here, before the header is written: a ray whose hit cannot be
 * printed is refused with nothing on standard output (docs/reliability.md). */
static int raycast_prepare(qrun_t *q) {
  size_t rays = q->tab[1].rows;
  for (size_t i = 0; i < rays; i++) {
    double tmax = q->tab[1].v[5 * i + 4];
    if (!isnan(tmax) && tmax < 0) {
      char msg[96];
      snprintf(msg, sizeof msg, "tmax is negative: %.17g (field 5)", tmax);
      return bad_row(q, 1, i, msg);
    }
  }
  int rc = build_collider(q);
  if (rc) return rc;
  q->hits = malloc((rays ? rays : 1) * sizeof *q->hits);
  if (!q->hits) return cli_status(q->a.cmd, "ray hits", QK_ERR_NOMEM);
  for (size_t i = 0; i < rays; i++) {
    const double *v = q->tab[1].v + 5 * i;
    qk_hit_t *h = &q->hits[i];
    qk_status_t st = qk_collider_raycast(q->col, (qk_point_t){v[0], v[1]}, (qk_point_t){v[2], v[3]},
                                         isnan(v[4]) ? INFINITY : v[4], h);
    if (st != QK_OK) { /* the reader let only finite values and tmax >= 0 through */
      char msg[128];
      snprintf(msg, sizeof msg, "ray %zu: %s", i, qk_strerror(st));
      return bad_row(q, 1, i, msg);
    }
    if (h->id != QK_NONE && !isfinite(h->t)) {
      /* a hit whose t overflows (a tiny direction, a far disc) would print as the miss's inf */
      char msg[256];
      snprintf(msg, sizeof msg,
               "ray %zu hits %u at a t beyond the largest double (direction %.17g,%.17g too "
               "short for the distance); scale the direction",
               i, (unsigned)h->id, v[2], v[3]);
      return bad_row(q, 1, i, msg);
    }
  }
  return CLI_OK;
}

static int raycast_answer(qrun_t *q, size_t i) {
  const qk_hit_t *h = &q->hits[i];
  if (h->id == QK_NONE)
    emit(q, i, SIZE_MAX, "%zu,-1,inf", i);
  else
    emit(q, i, h->id, "%zu,%u,%.17g", i, (unsigned)h->id, h->t);
  return CLI_OK;
}

static const qcmd_t raycast_boxes_cmd = {.allow = "b",
                                         .nfiles = 2,
                                         .kind = {IN_ITEMS, IN_RAYS},
                                         .head = "ray,box,t",
                                         .side = {"ray", "box"},
                                         .side_file = {1, 0},
                                         .usage = raycast_usage,
                                         .prepare = raycast_prepare,
                                         .answer = raycast_answer};

static const qcmd_t raycast_cmd = {.allow = "b",
                                   .nfiles = 2,
                                   .kind = {IN_ITEMS, IN_RAYS},
                                   .head = "ray,disc,t",
                                   .side = {"ray", "disc"},
                                   .side_file = {1, 0},
                                   .usage = raycast_usage,
                                   .prepare = raycast_prepare,
                                   .answer = raycast_answer,
                                   .boxes = &raycast_boxes_cmd};

int cmd_raycast(int argc, char **argv) { return run_query(argc, argv, &raycast_cmd); }

/* ---------------------------------------------------------------------------------- */
/* geo                                                                                  */

static void geo_usage(FILE *f) {
  fprintf(f,
          "usage: quadkit geo knn POINTS.csv QUERIES.csv -k K [--max-dist METRES] [options]\n"
          "       quadkit geo radius POINTS.csv QUERIES.csv -r METRES [options]\n"
          "Geodesic queries on the WGS84 ellipsoid: the x and y columns are lon,lat in\n"
          "degrees (latitude within [-90, 90]; any longitude, normalised); distances in\n"
          "metres along the geodesic (GeographicLib's algorithm).\n"
          "Output: knn    query,rank,point,metres  (rank 1..K; ties by smaller id)\n"
          "        radius query,point,metres       (by query then point)\n"
          "  --max-dist METRES  knn: only points within METRES (fewer than K rows then)\n" XY_HELP
          "  --query-xy X,Y  the same for QUERIES.csv only\n" KEEP_HELP("query, point or both")
              COMMON_HELP);
}

/* Latitudes must lie in [-90, 90]: say which line does not. */
static int check_lat(const qrun_t *q, int i) {
  for (size_t j = 0; j < q->n[i]; j++)
    if (q->pts[i][j].y < -90 || q->pts[i][j].y > 90) {
      char msg[96];
      snprintf(msg, sizeof msg, "latitude %.17g is outside [-90, 90]", q->pts[i][j].y);
      return bad_row(q, i, j, msg);
    }
  return CLI_OK;
}

static int geo_prepare(qrun_t *q) {
  int rc;
  if ((rc = check_lat(q, 0)) || (rc = check_lat(q, 1))) return rc;
  qk_tree_options_t opt;
  qk_tree_options_init(&opt);
  opt.capacity = (uint32_t)q->a.capacity;
  if ((rc = cli_status(q->a.cmd, cli_input_name(q->a.files[0]),
                       qk_geo_build(q->pts[0], q->n[0], &opt, &q->geo))))
    return rc;
  return scratch(q, q->a.has_k ? q->a.k : q->n[0], 0);
}

static int geo_knn_answer(qrun_t *q, size_t i) {
  size_t m = 0;
  qk_status_t st = qk_geo_knn(q->geo, q->pts[1][i], q->a.k, q->a.max_dist, q->nb, &m);
  if (st != QK_OK) return cli_status(q->a.cmd, cli_input_name(q->a.files[1]), st);
  for (size_t j = 0; j < m; j++)
    emit(q, i, q->nb[j].id, "%zu,%zu,%u,%.17g", i, j + 1, (unsigned)q->nb[j].id, q->nb[j].dist);
  return CLI_OK;
}

static int geo_radius_answer(qrun_t *q, size_t i) {
  size_t m = 0;
  qk_status_t st = qk_geo_radius_list(q->geo, q->pts[1][i], q->a.r, q->nb, q->cap, &m);
  if (st != QK_OK) return cli_status(q->a.cmd, cli_input_name(q->a.files[1]), st);
  qsort(q->nb, m, sizeof *q->nb, nb_by_id);
  for (size_t j = 0; j < m; j++)
    emit(q, i, q->nb[j].id, "%zu,%u,%.17g", i, (unsigned)q->nb[j].id, q->nb[j].dist);
  return CLI_OK;
}

static const qcmd_t geo_knn_cmd = {.allow = "k",
                                   .nfiles = 2,
                                   .kind = {IN_POINTS, IN_POINTS},
                                   .head = "query,rank,point,metres",
                                   .side = {"query", "point"},
                                   .side_file = {1, 0},
                                   .usage = geo_usage,
                                   .prepare = geo_prepare,
                                   .answer = geo_knn_answer};
static const qcmd_t geo_radius_cmd = {.allow = "r",
                                      .nfiles = 2,
                                      .kind = {IN_POINTS, IN_POINTS},
                                      .head = "query,point,metres",
                                      .side = {"query", "point"},
                                      .side_file = {1, 0},
                                      .usage = geo_usage,
                                      .prepare = geo_prepare,
                                      .answer = geo_radius_answer};

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
  argv[1] = "geo";
  return run_query(argc - 1, argv + 1, is_knn ? &geo_knn_cmd : &geo_radius_cmd);
}
