/*
 * `quadkit world`: replay a scene of moving objects and write the overlapping pairs of
 * every frame; `quadkit simulate`: a bouncing-objects scene with timings as JSON and an
 * SVG of the last frame.
 */
#define _POSIX_C_SOURCE 200809L
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cli.h"

/* ---- reading the scene ------------------------------------------------------------- */

/* One parsed row: up to 6 fields as text; n is 7 when there were more. */
typedef struct row {
  char *f[7];
  int n;
} row_t;

/* Split a line into fields in place: blanks around a field dropped; a field in double
 * quotes ("" inside for a quote) unquoted, as the other CSV inputs take them. NULL, or
 * what is malformed. (Not io/csv_read.c: the library's reader returns numbers only, and a
 * scene row holds a kind name and 64-bit ids, which doubles cannot hold exactly; the
 * field scanner it uses is private to io/. Same quoting rules and messages:
 * tests/cli/world.sh, review3.) */
static const char *split(char *line, row_t *r) {
  r->n = 0;
  char *s = line;
  for (;;) {
    while (*s == ' ' || *s == '\t') s++;
    char *field = s, *c;
    if (*s == '"') {
      char *w = s; /* the unquoted text is written over the field */
      for (s++;; s++) {
        if (!*s) return "unterminated quoted field";
        if (*s == '"' && s[1] != '"') break;
        if (*s == '"') s++; /* "" is one quote */
        *w++ = *s;
      }
      *w = '\0';
      s++;
      while (*s == ' ' || *s == '\t') s++;
      if (*s && *s != ',') return "text after a closing quote";
      c = *s ? s : NULL;
    } else {
      c = strchr(s, ',');
      char *end = c ? c : s + strlen(s);
      while (end > s && isspace((unsigned char)end[-1])) end--;
      *end = '\0';
    }
    if (r->n < 7) r->f[r->n++] = field;
    if (!c) break;
    s = c + 1;
  }
  return NULL;
}

/* A field as a number: cli_number's 1, 0, -1 (hexadecimal, which looks like a number
 * to the header test but is refused as a value) or -2 (below the smallest double). */
static int num(const char *s, double *v) { return cli_number(s, v); }

/* An id (or a frame): a whole number from 0 to 2^64 - 1. NULL, or an error message for
 * bad() saying what is wrong with it. */
static const char *parse_id(const char *s, uint64_t *id) {
  char *end;
  if (!isdigit((unsigned char)*s)) return "id is not a whole number: '%s'";
  errno = 0;
  unsigned long long v = strtoull(s, &end, 10);
  if (*end) return "id is not a whole number: '%s'";
  if (errno == ERANGE) return "id is above 2^64 - 1: '%s'";
  *id = v;
  return NULL;
}

typedef struct obj {
  uint64_t id;
  qk_shape_t s;
  qk_handle_t h;
  unsigned long line;   /* in the objects file */
  unsigned long mline;  /* the line of its last move in the moves file, 0 for none, */
  unsigned long mframe; /* and that move's frame */
} obj_t;

typedef struct move {
  unsigned long frame;
  size_t obj; /* index into the objects */
  double v[4];
  unsigned long line;
} move_t;

typedef struct scene {
  obj_t *o;
  size_t n, cap;
  size_t *by_id; /* object indices sorted by id */
  move_t *m;
  size_t nm, capm;
} scene_t;

static void scene_free(scene_t *s) {
  free(s->o);
  free(s->by_id);
  free(s->m);
}

/* The text of the line being read (after a byte order mark), for the column of a field:
 * split() leaves each field where it was in the line (a quoted one starts at its quote). */
static const char *g_row;
static size_t g_row_len;

/* The first 40 bytes of a field for a message, as the other readers quote a value (a
 * quoted field of 1.2 MB, line breaks and all, made a message of 1.2 MB); a UTF-8
 * character is not cut in two. buf holds at least 41 bytes. */
static const char *cut40(const char *val, char *buf) {
  size_t n = strlen(val);
  if (n <= 40) return val;
  n = 40;
  while (n > 0 && ((unsigned char)val[n] & 0xC0) == 0x80) n--;
  memcpy(buf, val, n);
  buf[n] = '\0';
  return buf;
}

/* "PATH:LINE[:COLUMN]: " and fmt with val; the column when val is a field of the line. A
 * field (any val but a whole message, fmt "%s") is quoted to its first 40 bytes. */
static int bad(const char *path, unsigned long line, const char *fmt, const char *val) {
  uintptr_t v = (uintptr_t)val, r = (uintptr_t)g_row;
  char buf[41];
  if (g_row && v >= r && v - r < g_row_len)
    cli_msg("quadkit world: %s:%lu:%lu: ", path, line, (unsigned long)(v - r) + 1);
  else
    cli_msg("quadkit world: %s:%lu: ", path, line);
  cli_msg(fmt, strcmp(fmt, "%s") ? cut40(val, buf) : val);
  fputc('\n', stderr);
  return CLI_BAD_INPUT;
}

static int kind_of(const char *s, qk_shape_kind_t *k) {
  static const char *names[] = {"disc", "box", "segment", "point"};
  for (int i = 0; i < 4; i++)
    if (!strcmp(s, names[i])) {
      *k = (qk_shape_kind_t)i;
      return 1;
    }
  return 0;
}

/* Values x, y, a, b of a shape of kind k from fields f (missing ones count as absent). */
static int shape_values(const char *path, unsigned long ln, qk_shape_kind_t k, char **f, int nf,
                        qk_shape_t *s) {
  int need = k == QK_SHAPE_POINT ? 2 : k == QK_SHAPE_DISC ? 3 : 4;
  double v[4] = {0, 0, 0, 0};
  if (nf < need) return bad(path, ln, "%s", "too few fields for this kind of shape");
  for (int i = 0; i < need; i++) {
    const int got = num(f[i], &v[i]);
    if (got == -2)
      return bad(path, ln, "value below the smallest double (it would read as 0): '%s'", f[i]);
    if (got != 1) return bad(path, ln, "not a decimal number: '%s'", f[i]);
    if (!isfinite(v[i])) return bad(path, ln, "coordinate is not finite: '%s'", f[i]);
  }
  /* Fields a kind does not use may be empty or hold a number (files that write all six
   * columns for every kind), but nothing else. */
  for (int i = need; i < nf; i++) {
    double unused;
    const int got = f[i][0] ? num(f[i], &unused) : 1;
    if (got != 1 && got != -2) /* (a number below the smallest double is still a number) */
      return bad(path, ln,
                 "field '%s' is not used by this kind of shape: leave it empty or a number", f[i]);
  }
  *s = (qk_shape_t){k, v[0], v[1], v[2], v[3]};
  if (k == QK_SHAPE_DISC && v[2] < 0) return bad(path, ln, "disc radius is negative: '%s'", f[2]);
  for (int i = 0; i < need; i++) {
    double a = fabs(v[i]);
    if (a != 0 && (a < 0x1p-100 || a > 0x1p100))
      return bad(path, ln, "value outside [2^-100, 2^100] in magnitude: '%s'", f[i]);
  }
  return CLI_OK;
}

static const scene_t *g_scene; /* for qsort by id */
static int by_id_cmp(const void *x, const void *y) {
  uint64_t a = g_scene->o[*(const size_t *)x].id, b = g_scene->o[*(const size_t *)y].id;
  return (a > b) - (a < b);
}

static size_t find_id(const scene_t *s, uint64_t id) {
  size_t lo = 0, hi = s->n;
  while (lo < hi) {
    size_t mid = (lo + hi) / 2;
    if (s->o[s->by_id[mid]].id < id)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < s->n && s->o[s->by_id[lo]].id == id ? s->by_id[lo] : SIZE_MAX;
}

/* Read lines of a CSV file, skipping blank lines and a header (a first line none of whose
 * fields is a number); fn gets each data row. */
static int each_row(const char *arg,
                    int (*fn)(const char *path, unsigned long ln, row_t *r, scene_t *s),
                    scene_t *s) {
  FILE *f = cli_input_open("world", arg); /* ("-": standard input) */
  if (!f) return CLI_BAD_INPUT;
  const char *path = cli_input_name(arg); /* (the name messages give it) */
  /* The tool's line reader: a NUL byte or a line past CLI_MAX_LINE stops it at once. */
  cli_lines_t rd;
  cli_lines_init(&rd, f);
  unsigned long ln = 0;
  int rc = CLI_OK, first = 1;
  long len;
  const char *rwhy;
  /* A record is a line, or several when a quoted field holds line breaks: messages name
   * the physical line where it starts. */
  while ((len = cli_read_record(&rd, &rwhy)) >= 0) {
    char *line = rd.line;
    ln = rd.first;
    size_t n = (size_t)len;
    if (rwhy) { /* the input ends inside a quoted field */
      rc = bad(path, ln, "%s", rwhy);
      break;
    }
    char *p = line;
    /* A UTF-8 byte order mark (editors on Windows write one) is not part of the first
     * field: left there, it would make a first data row look like a header. */
    if (ln == 1 && !strncmp(p, "\xEF\xBB\xBF", 3)) p += 3;
    while (isspace((unsigned char)*p)) p++;
    if (!*p) continue;
    row_t r;
    const char *why = split(p, &r);
    if (why) {
      rc = bad(path, ln, "%s", why);
      break;
    }
    /* A header names its columns: no field of it is a number. A first row with a
     * malformed id but numbers after it is data, and its error is reported (it was
     * taken for a header and the object dropped without a word). */
    int numbers = 0;
    double v;
    for (int i = 0; i < r.n && i < 6; i++) numbers += num(r.f[i], &v) != 0;
    if (first && numbers == 0) {
      first = 0;
      continue;
    }
    first = 0;
    g_row = line + (p - line >= 3 && ln == 1 && !strncmp(line, "\xEF\xBB\xBF", 3) ? 3 : 0);
    /* (columns on the record's first line only) */
    const char *lf = memchr(g_row, '\n', n - (size_t)(g_row - line));
    g_row_len = lf ? (size_t)(lf - g_row) : n - (size_t)(g_row - line);
    rc = fn(path, ln, &r, s);
    g_row = NULL;
    if (rc) break;
  }
  cli_lines_free(&rd);
  if (!rc) rc = cli_lines_status("world", path, &rd, len, rwhy, 1);
  cli_input_close(f);
  return rc;
}

/* How many fields a row has, for a message (split() stops counting past 6). */
static const char *fields_text(int n) {
  static const char *const t[] = {"no fields", "1 field", "2 fields", "3 fields"};
  return n < 4 ? t[n] : "more than 6 fields";
}

static int object_row(const char *path, unsigned long ln, row_t *r, scene_t *s) {
  if (r->n < 4 || r->n > 6)
    return bad(path, ln, "expected id,kind,x,y[,a,b]: the line has %s", fields_text(r->n));
  uint64_t id;
  const char *why = parse_id(r->f[0], &id);
  if (why) return bad(path, ln, why, r->f[0]);
  qk_shape_kind_t k;
  if (!kind_of(r->f[1], &k))
    return bad(path, ln, "unknown kind '%s' (disc, box, segment or point)", r->f[1]);
  qk_shape_t sh;
  int rc = shape_values(path, ln, k, r->f + 2, r->n - 2, &sh);
  if (rc) return rc;
  if (s->n == s->cap) {
    size_t cap = s->cap ? 2 * s->cap : 256;
    obj_t *o = realloc(s->o, cap * sizeof *o);
    if (!o) return CLI_INTERNAL;
    s->o = o;
    s->cap = cap;
  }
  s->o[s->n++] = (obj_t){id, sh, QK_HANDLE_NONE, ln, 0, 0};
  return CLI_OK;
}

static int move_row(const char *path, unsigned long ln, row_t *r, scene_t *s) {
  if (r->n < 4 || r->n > 6)
    return bad(path, ln, "expected frame,id,x,y[,a,b]: the line has %s", fields_text(r->n));
  uint64_t frame, id;
  if (parse_id(r->f[0], &frame) || frame > 100000000)
    return bad(path, ln, "frame is not a whole number from 0 to 1e8: '%s'", r->f[0]);
  if (s->nm && frame < s->m[s->nm - 1].frame)
    return bad(path, ln, "frames out of order: '%s' after a later frame", r->f[0]);
  const char *why = parse_id(r->f[1], &id);
  if (why) return bad(path, ln, why, r->f[1]);
  size_t i = find_id(s, id);
  if (i == SIZE_MAX) return bad(path, ln, "unknown id '%s'", r->f[1]);
  /* Two shapes for one object in one frame: only the last would count, the other row
   * silently lost (moves are in frame order, so the object's last move tells). */
  if (s->o[i].mline && s->o[i].mframe == frame) {
    char buf[41];
    cli_msg("quadkit world: %s:%lu: id %s moves twice in frame %lu (also on line %lu): one "
            "shape per object and frame\n",
            path, ln, cut40(r->f[1], buf), (unsigned long)frame, s->o[i].mline);
    return CLI_BAD_INPUT;
  }
  qk_shape_t sh;
  int rc = shape_values(path, ln, s->o[i].s.kind, r->f + 2, r->n - 2, &sh);
  if (rc) return rc;
  s->o[i].mline = ln, s->o[i].mframe = (unsigned long)frame;
  if (s->nm == s->capm) {
    size_t cap = s->capm ? 2 * s->capm : 256;
    move_t *m = realloc(s->m, cap * sizeof *m);
    if (!m) return CLI_INTERNAL;
    s->m = m;
    s->capm = cap;
  }
  s->m[s->nm++] = (move_t){(unsigned long)frame, i, {sh.x, sh.y, sh.a, sh.b}, ln};
  return CLI_OK;
}

static void world_usage(FILE *f) {
  fprintf(f, "usage: quadkit world OBJECTS.csv MOVES.csv [--pairs all|began|ended] [-o FILE]\n"
             "Replay a scene of moving objects and write the overlapping pairs of every frame.\n"
             "OBJECTS.csv rows: id,kind,x,y,a,b  (kind disc: centre x,y radius a; box: corners\n"
             "  x,y and a,b; segment: from x,y to a,b; point: x,y). Ids are whole numbers.\n"
             "MOVES.csv rows: frame,id,x,y,a,b  (the object's new shape from that frame on;\n"
             "  frames from 0, in order; the kind stays the object's). Either file may\n"
             "  start with a header line (no field a number); fields may be quoted.\n"
             "Shapes are closed: touching counts as overlapping; decided exactly.\n"
             "Output: frame,a,b  (a < b, sorted) for every overlapping pair of every frame, or\n"
             "  with --pairs began / ended the pairs that began / ended at that frame.\n"
             "  -o FILE   write to FILE instead of standard output\n");
}

typedef struct idpair {
  uint64_t a, b;
} idpair_t;

static int idpair_cmp(const void *x, const void *y) {
  const idpair_t *p = x, *q = y;
  if (p->a != q->a) return p->a < q->a ? -1 : 1;
  return (p->b > q->b) - (p->b < q->b);
}

int cmd_world(int argc, char **argv) {
  const char *cmd = "world", *files[2] = {NULL, NULL}, *out = "-";
  qk_pairs_which_t which = QK_PAIRS_ALL;
  int nfiles = 0;
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
      world_usage(stdout);
      return CLI_OK;
    } else if (!strcmp(argv[i], "--pairs")) {
      const char *v = i + 1 < argc ? argv[++i] : "";
      if (!strcmp(v, "all"))
        which = QK_PAIRS_ALL;
      else if (!strcmp(v, "began"))
        which = QK_PAIRS_BEGAN;
      else if (!strcmp(v, "ended"))
        which = QK_PAIRS_ENDED;
      else {
        cli_error(cmd, "--pairs must be all, began or ended, not '%s'", v);
        return CLI_USAGE;
      }
    } else if (!strcmp(argv[i], "-o")) {
      if (i + 1 >= argc) {
        cli_error(cmd, "-o needs a value");
        return CLI_USAGE;
      }
      out = argv[++i];
    } else if (argv[i][0] == '-' && argv[i][1]) {
      cli_error(cmd, "unknown option '%s'", argv[i]);
      world_usage(stderr);
      return CLI_USAGE;
    } else if (nfiles < 2) {
      files[nfiles++] = argv[i];
    } else {
      cli_error(cmd, "too many arguments");
      return CLI_USAGE;
    }
  }
  if (nfiles != 2) {
    world_usage(stderr);
    return CLI_USAGE;
  }
  int rc = cli_inputs_once(cmd, files, 2);
  if (rc) return rc;
  /* The output is opened before the inputs are read (they are noted first, so that an
   * output naming one, or its pipe, is still refused): a path that cannot be written fails
   * at once, not after reading and replaying the moves. */
  cli_note_input(files[0]);
  cli_note_input(files[1]);
  cli_out_t o;
  if ((rc = cli_out_open(cmd, out, &o))) return rc;
  scene_t s = {0};
  qk_world_t *w = NULL;
  qk_world_pair_t *pairs = NULL;
  idpair_t *ids = NULL;
  rc = each_row(files[0], object_row, &s);
  if (rc) goto done;
  if (s.n == 0) {
    cli_msg("quadkit world: %s: no objects\n", cli_input_name(files[0]));
    rc = CLI_BAD_INPUT;
    goto done;
  }
  s.by_id = malloc(s.n * sizeof *s.by_id);
  if (!s.by_id) {
    rc = cli_status(cmd, "reading", QK_ERR_NOMEM);
    goto done;
  }
  for (size_t i = 0; i < s.n; i++) s.by_id[i] = i;
  g_scene = &s;
  qsort(s.by_id, s.n, sizeof *s.by_id, by_id_cmp);
  for (size_t i = 1; i < s.n; i++)
    if (s.o[s.by_id[i]].id == s.o[s.by_id[i - 1]].id) {
      unsigned long a = s.o[s.by_id[i - 1]].line, b = s.o[s.by_id[i]].line;
      cli_msg("quadkit world: %s:%lu: id %llu appears twice (also on line %lu)\n",
              cli_input_name(files[0]), a > b ? a : b, (unsigned long long)s.o[s.by_id[i]].id,
              a < b ? a : b);
      rc = CLI_BAD_INPUT;
      goto done;
    }
  if ((rc = each_row(files[1], move_row, &s))) goto done;
  qk_status_t st = qk_world_new(NULL, &w);
  for (size_t i = 0; st == QK_OK && i < s.n; i++) st = qk_world_add(w, &s.o[i].s, i, &s.o[i].h);
  if (st != QK_OK) {
    rc = cli_status(cmd, "building the world", st);
    goto done;
  }
  fprintf(o.f, "frame,a,b\n");
  unsigned long frames = s.nm ? s.m[s.nm - 1].frame + 1 : 1;
  size_t mi = 0, cap = 0, np = 0;
  for (unsigned long f = 0; f < frames && rc == CLI_OK; f++) {
    int moved = 0;
    for (; mi < s.nm && s.m[mi].frame == f; mi++) {
      obj_t *ob = &s.o[s.m[mi].obj];
      qk_shape_t sh = {ob->s.kind, s.m[mi].v[0], s.m[mi].v[1], s.m[mi].v[2], s.m[mi].v[3]};
      moved = 1;
      if ((st = qk_world_move(w, ob->h, &sh)) != QK_OK) break;
    }
    if (f > 0 && !moved) {
      /* Nothing moved: the same pairs as the frame before, none began or ended. (An
       * update per empty frame made two moves 10^8 frames apart run for minutes.) */
      if (which == QK_PAIRS_ALL)
        for (size_t i = 0; i < np; i++)
          fprintf(o.f, "%lu,%llu,%llu\n", f, (unsigned long long)ids[i].a,
                  (unsigned long long)ids[i].b);
      if (ferror(o.f)) break; /* (cli_out_close reports it) */
      continue;
    }
    if (st == QK_OK) st = qk_world_update(w);
    np = 0;
    if (st == QK_OK) st = qk_world_pairs_list(w, which, NULL, 0, &np);
    if (st == QK_OK && np > cap) {
      free(pairs);
      free(ids);
      cap = np;
      pairs = malloc(cap * sizeof *pairs);
      ids = malloc(cap * sizeof *ids);
      if (!pairs || !ids) st = QK_ERR_NOMEM;
    }
    if (st == QK_OK) st = qk_world_pairs_list(w, which, pairs, cap, &np);
    if (st != QK_OK) {
      rc = cli_status(cmd, "replaying", st);
      break;
    }
    /* Report by the file's ids: objects were added in file order and never removed,
     * so a handle's slot is the object's index. */
    for (size_t i = 0; i < np; i++) {
      uint64_t a = s.o[QK_HANDLE_SLOT(pairs[i].a)].id, b = s.o[QK_HANDLE_SLOT(pairs[i].b)].id;
      ids[i] = a < b ? (idpair_t){a, b} : (idpair_t){b, a};
    }
    if (np > 1) qsort(ids, np, sizeof *ids, idpair_cmp);
    for (size_t i = 0; i < np; i++)
      fprintf(o.f, "%lu,%llu,%llu\n", f, (unsigned long long)ids[i].a,
              (unsigned long long)ids[i].b);
  }
done:;
  int rc2 = cli_out_close(cmd, &o, rc == CLI_OK); /* (on an error: nothing written) */
  if (rc == CLI_OK) rc = rc2;
  free(pairs);
  free(ids);
  qk_world_free(w);
  scene_free(&s);
  return rc;
}

/* ---- simulate ---------------------------------------------------------------------- */

/* An output (NULL: none) whose buffered text went out without an error. */
static int flushed(FILE *f) { return !f || (fflush(f) == 0 && !ferror(f)); }

static void simulate_usage(FILE *f) {
  fprintf(f, "usage: quadkit simulate [--n N] [--frames F] [--seed S] [--svg FILE] [-o FILE]\n"
             "Bounce N objects (discs, boxes, segments and points; sizes 0.5 to 2) around a\n"
             "square world for F frames, finding the overlapping pairs every frame.\n"
             "Prints JSON: per-frame pairs, began and ended counts and a timing summary\n"
             "(milliseconds per frame for moving every object plus the update). --svg draws\n"
             "the last frame, objects in an overlapping pair in red; -o writes the JSON to\n"
             "FILE instead of standard output. Defaults: --n 2000 --frames 100 --seed 1.\n");
}

static double now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

/* splitmix64: small, seeded, the same everywhere. */
static double rnd(uint64_t *s) {
  uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return (double)((z ^ (z >> 31)) >> 11) * 0x1p-53;
}

typedef struct body {
  qk_shape_t s;
  double vx, vy;
  qk_handle_t h;
} body_t;

static void translate(qk_shape_t *s, double dx, double dy) {
  s->x += dx;
  s->y += dy;
  if (s->kind == QK_SHAPE_BOX || s->kind == QK_SHAPE_SEGMENT) {
    s->a += dx;
    s->b += dy;
  }
}

/* Draw into an opened output; returns nonzero when writing failed. */
static int write_svg(cli_out_t *so, const body_t *b, size_t n, const unsigned char *hit,
                     double side) {
  cli_out_t o = *so;
  double k = 800 / side;
  fprintf(o.f, "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"800\" height=\"800\" "
               "viewBox=\"0 0 800 800\">\n<rect width=\"800\" height=\"800\" fill=\"white\" "
               "stroke=\"black\"/>\n");
  for (size_t i = 0; i < n; i++) {
    const qk_shape_t *s = &b[i].s;
    const char *c = hit[i] ? "#d62728" : "#7f7f7f";
    double y = 800 - s->y * k;
    switch (s->kind) {
    case QK_SHAPE_DISC:
      fprintf(o.f,
              "<circle cx=\"%.2f\" cy=\"%.2f\" r=\"%.2f\" fill=\"%s\" fill-opacity=\"0.5\"/>\n",
              s->x * k, y, s->a * k, c);
      break;
    case QK_SHAPE_BOX:
      fprintf(o.f,
              "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\" fill=\"%s\" "
              "fill-opacity=\"0.5\"/>\n",
              fmin(s->x, s->a) * k, 800 - fmax(s->y, s->b) * k, fabs(s->a - s->x) * k,
              fabs(s->b - s->y) * k, c);
      break;
    case QK_SHAPE_SEGMENT:
      fprintf(o.f, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" stroke=\"%s\"/>\n",
              s->x * k, y, s->a * k, 800 - s->b * k, c);
      break;
    default:
      fprintf(o.f, "<circle cx=\"%.2f\" cy=\"%.2f\" r=\"1.5\" fill=\"%s\"/>\n", s->x * k, y, c);
    }
  }
  fprintf(o.f, "</svg>\n");
  return ferror(o.f) != 0;
}

static int mark_pair(qk_handle_t a, qk_handle_t b, void *ud) {
  unsigned char *hit = ud;
  hit[QK_HANDLE_SLOT(a)] = hit[QK_HANDLE_SLOT(b)] = 1;
  return 0;
}

int cmd_simulate(int argc, char **argv) {
  const char *cmd = "simulate", *svg = NULL, *out = "-";
  unsigned long n = 2000, frames = 100, seed = 1;
  for (int i = 1; i < argc; i++) {
    const char *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
      simulate_usage(stdout);
      return CLI_OK;
    } else if (!strcmp(argv[i], "--n")) {
      if (cli_parse_u32(cmd, "--n", v, 1, 10000000, &n)) return CLI_USAGE;
      i++;
    } else if (!strcmp(argv[i], "--frames")) {
      if (cli_parse_u32(cmd, "--frames", v, 1, 1000000, &frames)) return CLI_USAGE;
      i++;
    } else if (!strcmp(argv[i], "--seed")) {
      if (cli_parse_u32(cmd, "--seed", v, 0, 4294967295ul, &seed)) return CLI_USAGE;
      i++;
    } else if (!strcmp(argv[i], "--svg") || !strcmp(argv[i], "-o")) {
      if (!v) {
        cli_error(cmd, "%s needs a value", argv[i]);
        return CLI_USAGE;
      }
      *(argv[i][1] == 'o' ? &out : &svg) = v;
      i++;
    } else {
      cli_error(cmd, "unknown argument '%s'", argv[i]);
      simulate_usage(stderr);
      return CLI_USAGE;
    }
  }
  /* Both outputs are opened (as temporaries) before the work: a path that cannot be
   * written is an error at once, not after the whole simulation and its JSON. */
  cli_out_t o, so;
  memset(&so, 0, sizeof so);
  int orc = cli_out_open(cmd, out, &o);
  if (!orc && svg && (orc = cli_out_open(cmd, svg, &so))) cli_out_close(cmd, &o, 0);
  if (orc) return orc;
  /* Objects of mean area ~1 at density ~0.4: each overlaps about one other (measured:
   * 2 pairs / n is 1.0-1.1 at n = 500 to 20,000). */
  double side = sqrt((double)n * 2.5);
  uint64_t rs = seed;
  body_t *b = malloc(n * sizeof *b);
  unsigned long *counts = malloc(3 * frames * sizeof *counts);
  unsigned char *hit = calloc(n, 1);
  qk_world_t *w = NULL;
  int rc = CLI_OK;
  if (!b || !counts || !hit) {
    rc = cli_status(cmd, "setting up", QK_ERR_NOMEM);
    goto done;
  }
  qk_status_t st = qk_world_new(NULL, &w);
  for (unsigned long i = 0; i < n && st == QK_OK; i++) {
    double x = rnd(&rs) * side, y = rnd(&rs) * side, e = 0.5 + 1.5 * rnd(&rs);
    double ang = rnd(&rs) * 6.283185307179586, sp = 0.25 + 0.5 * rnd(&rs);
    qk_shape_t s = {QK_SHAPE_DISC, x, y, e / 2, 0};
    switch (i % 4) {
    case 1:
      s = (qk_shape_t){QK_SHAPE_BOX, x, y, x + e, y + e * (0.5 + rnd(&rs))};
      break;
    case 2:
      s = (qk_shape_t){QK_SHAPE_SEGMENT, x, y, x + e * cos(ang), y + e * sin(ang)};
      break;
    case 3:
      s = (qk_shape_t){QK_SHAPE_POINT, x, y, 0, 0};
      break;
    default:
      break;
    }
    b[i] = (body_t){s, sp * cos(ang), sp * sin(ang), QK_HANDLE_NONE};
    st = qk_world_add(w, &b[i].s, i, &b[i].h);
  }
  double total = 0, tmin = INFINITY, tmax = 0;
  for (unsigned long f = 0; f < frames && st == QK_OK; f++) {
    double t0 = now_ms();
    for (unsigned long i = 0; i < n && st == QK_OK; i++) {
      qk_shape_t *s = &b[i].s;
      translate(s, b[i].vx, b[i].vy);
      /* bounce off the walls (the shape's box against the world square) */
      double x0 = s->x, x1 = s->x, y0 = s->y, y1 = s->y;
      if (s->kind == QK_SHAPE_DISC) x0 -= s->a, x1 += s->a, y0 -= s->a, y1 += s->a;
      if (s->kind == QK_SHAPE_BOX || s->kind == QK_SHAPE_SEGMENT)
        x0 = fmin(s->x, s->a), x1 = fmax(s->x, s->a), y0 = fmin(s->y, s->b), y1 = fmax(s->y, s->b);
      if ((x0 < 0 && b[i].vx < 0) || (x1 > side && b[i].vx > 0)) b[i].vx = -b[i].vx;
      if ((y0 < 0 && b[i].vy < 0) || (y1 > side && b[i].vy > 0)) b[i].vy = -b[i].vy;
      st = qk_world_move(w, b[i].h, s);
    }
    if (st == QK_OK) st = qk_world_update(w);
    double dt = now_ms() - t0;
    total += dt;
    tmin = fmin(tmin, dt);
    tmax = fmax(tmax, dt);
    size_t np[3] = {0, 0, 0};
    for (int k = 0; k < 3 && st == QK_OK; k++)
      st = qk_world_pairs_list(w, (qk_pairs_which_t)k, NULL, 0, &np[k]);
    for (int k = 0; k < 3; k++) counts[3 * f + (unsigned long)k] = np[k];
  }
  if (st != QK_OK) {
    rc = cli_status(cmd, "simulating", st);
    goto done;
  }
  /* The picture first, and flushed: when it cannot be written, nothing goes to the JSON's
   * output either (stdout, written in place, would keep what it was given). */
  if (svg) {
    if ((st = qk_world_pairs(w, QK_PAIRS_ALL, mark_pair, hit)) != QK_OK) {
      rc = cli_status(cmd, "simulating", st);
      goto done;
    }
    if (write_svg(&so, b, n, hit, side) || !flushed(so.f)) {
      rc = CLI_INTERNAL;
      goto done;
    }
  }
  const char *names[3] = {"pairs", "began", "ended"};
  fprintf(o.f, "{\"n\": %lu, \"frames\": %lu, \"seed\": %lu, \"side\": %.6g,\n", n, frames, seed,
          side);
  for (int k = 0; k < 3; k++) {
    fprintf(o.f, " \"%s\": [", names[k]);
    for (unsigned long f = 0; f < frames; f++)
      fprintf(o.f, "%s%lu", f ? ", " : "", counts[3 * f + (unsigned long)k]);
    fprintf(o.f, "],\n");
  }
  fprintf(o.f,
          " \"ms_per_frame\": {\"mean\": %.4f, \"min\": %.4f, \"max\": %.4f},\n"
          " \"bytes\": %zu}\n",
          total / (double)frames, tmin, tmax, qk_world_bytes(w));
done:
  /* Both flushed before either is renamed into place: a write that fails only when its
   * buffer goes out (-o /dev/full) left the picture behind. The one that failed says
   * why when it is closed. */
  if (rc == CLI_OK && !(flushed(o.f) && (!svg || flushed(so.f)))) rc = CLI_INTERNAL;
  /* The picture first: when it fails, the JSON file is not left behind either. */
  if (svg) {
    int rc2 = cli_out_close(cmd, &so, rc == CLI_OK);
    if (!rc) rc = rc2;
  }
  {
    int rc2 = cli_out_close(cmd, &o, rc == CLI_OK);
    if (!rc) rc = rc2;
  }
  qk_world_free(w);
  free(b);
  free(counts);
  free(hit);
  return rc;
}
