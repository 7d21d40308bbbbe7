/*
 * `quadkit join` (which feature of a polygon layer holds each point of a CSV file) and
 * `quadkit regions` (layer and index statistics, SVG). Points stream through in chunks,
 * so memory holds the layer and one chunk only.
 */
#define _XOPEN_SOURCE 700
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli.h"

#define CHUNK 65536

/* ---- reading the layer ---------------------------------------------------------------- */

static int read_layer(const char *cmd, const char *path, int planar, qk_region_t **out) {
  cli_note_input(path); /* (an output naming the layer is refused) */
  qk_region_options_t o;
  qk_region_options_init(&o);
  o.planar = planar;
  qk_error_t e;
  qk_status_t st = qk_region_read(path, &o, out, &e);
  if (st == QK_OK) return CLI_OK;
  if (e.line)
    cli_error(cmd, "%s:%lu:%lu: %s", path, e.line, e.column, e.message);
  else
    cli_error(cmd, "%s: %s", path, e.message[0] ? e.message : qk_strerror(st));
  return st == QK_ERR_NOMEM || st == QK_ERR_UNSUPPORTED ? CLI_INTERNAL : CLI_BAD_INPUT;
}

static int parse_boundary(const char *cmd, const char *s, qk_boundary_t *b) {
  if (s && !strcmp(s, "semi-open"))
    *b = QK_BOUNDARY_SEMI_OPEN;
  else if (s && !strcmp(s, "closed"))
    *b = QK_BOUNDARY_CLOSED;
  else if (s && !strcmp(s, "open"))
    *b = QK_BOUNDARY_OPEN;
  else {
    cli_error(cmd, "--boundary must be semi-open, closed or open, not '%s'", s ? s : "");
    return 1;
  }
  return 0;
}

/* ---- CSV fields --------------------------------------------------------------------------- */

/* Copy field `want` (0-based) of a CSV line into buf (quotes removed); returns 1 when
 * the line has that field, 0 when it has fewer (with want < 0: the number of fields, buf
 * unused), -1 - i when field i (that field or one
 * before it) is a malformed quoted field (*why says how), with the library reader's rules
 * (io/csv_scan.c): blanks may stand around the quotes, nothing else ("0.5"x and an unterminated
 * quote were read as 0.5 here while every other command refused them). */
static int csv_field(const char *line, int want, char *buf, size_t cap, const char **why) {
  const char *s = line;
  for (int i = 0;; i++) {
    size_t n = 0;
    const char *q = s;
    while (*q == ' ' || *q == '\t') q++;
    if (*q == '"') {
      s = q + 1;
      for (;;) {
        if (*s == '"' && s[1] == '"') {
          if (i == want && n + 1 < cap) buf[n++] = '"';
          s += 2;
        } else if (*s == '"') {
          s++;
          break;
        } else if (!*s) {
          if (why) *why = "unterminated quoted field";
          return -1 - i;
        } else {
          if (i == want && n + 1 < cap) buf[n++] = *s;
          s++;
        }
      }
      while (*s == ' ' || *s == '\t') s++;
      if (*s && *s != ',') {
        if (why) *why = "text after a closing quote";
        return -1 - i;
      }
    } else {
      while (*s && *s != ',') {
        if (i == want && n + 1 < cap) buf[n++] = *s;
        s++;
      }
    }
    if (i == want) {
      buf[n] = '\0';
      return 1;
    }
    if (*s != ',') return want < 0 ? i + 1 : 0;
    s++;
  }
}

/* The start of the field after the one at s (NULL after the last field), with
 * csv_field's quoting rules: a walk over a header's fields with it is linear, where
 * csv_field(header, i, ...) for i = 0, 1, ... read the line from its start each time
 * (a header of 100,000 names kept `join` busy for minutes before its first row). */
static const char *field_end(const char *s) {
  const char *q = s;
  while (*q == ' ' || *q == '\t') q++;
  if (*q == '"') {
    for (s = q + 1; *s && !(*s == '"' && s[1] != '"'); s += *s == '"' ? 2 : 1) continue;
    if (*s) s++;
  }
  while (*s && *s != ',') s++;
  return *s ? s + 1 : NULL;
}

/* Where field `want` (0-based; the line holds it, well formed up to it) starts: its
 * physical line, counted from the record's first line `first` (a quoted field before it
 * may hold line breaks), and its 1-based byte column on that line, blanks before it
 * included, as the library's reader counts them (the other commands' messages). bom: the
 * bytes of a byte order mark cut from the first line, which a column on it counts. */
static void field_at(const char *line, int want, unsigned long first, size_t bom, unsigned long *ln,
                     unsigned long *col) {
  const char *s = line;
  for (int i = 0; i < want && s; i++) s = field_end(s);
  if (!s) s = line + strlen(line); /* (not reached: the line holds the field) */
  const char *bol = line;
  *ln = first;
  for (const char *p = line; p < s; p++)
    if (*p == '\n') ++*ln, bol = p + 1;
  *col = (unsigned long)(s - bol) + 1 + (bol == line ? bom : 0);
}

/* A malformed field k (1-based) of join's points file, named with the line and column
 * where it starts, as the other commands' reader names it. */
static void field_error(const char *path, const char *line, int k, long lineno, size_t bom,
                        const char *why) {
  unsigned long fl, fc;
  field_at(line, k - 1, (unsigned long)lineno, bom, &fl, &fc);
  cli_msg("quadkit join: %s:%lu:%lu: field %d: %s\n", path, fl, fc, k, why);
}

/* A field as a number, blanks around allowed (cli_number: 1, 0, -1 for hexadecimal, -2 below
 * the smallest double). */
static int number(char *f, double *v) {
  while (*f == ' ' || *f == '\t') f++;
  size_t n = strlen(f);
  while (n > 0 && (f[n - 1] == ' ' || f[n - 1] == '\t')) f[--n] = '\0'; /* (our copy) */
  return n ? cli_number(f, v) : 0;
}

/* --xy X,Y: column names or 1-based numbers; resolved against the header. */
typedef struct xy_spec {
  char name[2][128];
  int col[2]; /* 0-based, -1 until resolved */
} xy_spec_t;

/* Cut blanks (spaces, tabs) from both ends of s, in place; returns its new start. */
static char *trim(char *s) {
  while (*s == ' ' || *s == '\t') s++;
  size_t n = strlen(s);
  while (n > 0 && (s[n - 1] == ' ' || s[n - 1] == '\t')) s[--n] = '\0';
  return s;
}

static int parse_xy(const char *cmd, const char *s, xy_spec_t *xy) {
  const char *comma = s ? strchr(s, ',') : NULL;
  if (!comma || comma == s || !comma[1] || strchr(comma + 1, ',')) {
    cli_error(cmd, "--xy needs two columns X,Y (names or 1-based numbers), not '%s'", s ? s : "");
    return 1;
  }
  size_t la = (size_t)(comma - s);
  if (la >= sizeof xy->name[0] || strlen(comma + 1) >= sizeof xy->name[1]) {
    cli_error(cmd, "--xy: column name too long");
    return 1;
  }
  char part[2][128];
  memcpy(part[0], s, la);
  part[0][la] = '\0';
  strcpy(part[1], comma + 1);
  for (int i = 0; i < 2; i++) {
    /* blanks around a name or number dropped, as the library's reader takes --xy */
    const char *t = trim(part[i]);
    if (!*t) {
      cli_error(cmd, "--xy needs two columns X,Y (names or 1-based numbers), not '%s'", s);
      return 1;
    }
    memmove(xy->name[i], t, strlen(t) + 1);
  }
  for (int i = 0; i < 2; i++) {
    char *end;
    long v = strtol(xy->name[i], &end, 10);
    xy->col[i] = -1;
    if (!*end && v >= 1 && v <= 100000)
      xy->col[i] = (int)v - 1;
    else if (!*end) {
      cli_error(cmd, "--xy: column number %s must be from 1 to 100000", xy->name[i]);
      return 1;
    }
  }
  /* x and y from one column would put every point on the diagonal, without a word. */
  if (xy->col[0] >= 0 ? xy->col[0] == xy->col[1] : !strcmp(xy->name[0], xy->name[1])) {
    cli_error(cmd, "--xy %s: x and y name the same column", s);
    return 1;
  }
  return 0;
}

/* The header field starting at f as a column name, in buf: its quotes undone, and blanks
 * around an unquoted name dropped, as the library's reader compares names (io/csv_read.c:
 * "x ,y" has a column x for every other command; join said "no column named 'x'").
 * Returns the name, or NULL when there is no field at f. */
static const char *header_name(const char *f, char *buf, size_t cap) {
  if (csv_field(f, 0, buf, cap, NULL) != 1) return NULL;
  const char *q = f;
  while (*q == ' ' || *q == '\t') q++;
  return *q == '"' ? buf : trim(buf);
}

/* Resolve names against the header line (its line, and the bytes of a byte order mark cut
 * from it, for messages); returns 0 or prints why not, as the library's reader says it. */
static int resolve_xy(const char *cmd, const char *path, const char *header, long lineno,
                      size_t bom, xy_spec_t *xy) {
  char buf[256];
  for (int k = 0; k < 2; k++) {
    if (xy->col[k] >= 0) continue;
    if (!header) {
      cli_error(cmd, "%s: --xy names column '%s' but the file has no header line", path,
                xy->name[k]);
      return 1;
    }
    int i = 0;
    const char *b;
    for (const char *f = header; f && (b = header_name(f, buf, sizeof buf));
         f = field_end(f), i++) {
      if (strcmp(b, xy->name[k])) continue;
      if (xy->col[k] >= 0) { /* as the library's reader: a name twice is ambiguous */
        unsigned long fl, fc;
        field_at(header, i, (unsigned long)lineno, bom, &fl, &fc);
        cli_error(cmd,
                  "%s:%lu:%lu: column name '%s' appears twice in the header (fields %d and %d)",
                  path, fl, fc, xy->name[k], xy->col[k] + 1, i + 1);
        return 1;
      }
      xy->col[k] = i;
    }
    if (xy->col[k] < 0) {
      int nf = csv_field(header, -1, NULL, 0, NULL);
      cli_error(cmd, "%s:%ld: no column named '%s' in the header (%d field%s: '%.100s')", path,
                lineno, xy->name[k], nf, nf == 1 ? "" : "s", header);
      return 1;
    }
  }
  if (xy->col[0] == xy->col[1]) { /* a name and a number for one column */
    cli_error(cmd, "%s:%ld: --xy %s,%s: x and y name the same column (field %d)", path, lineno,
              xy->name[0], xy->name[1], xy->col[0] + 1);
    return 1;
  }
  return 0;
}

static void put_csv(FILE *f, const char *s) {
  if (!strpbrk(s, ",\"\n\r")) {
    fputs(s, f);
    return;
  }
  fputc('"', f);
  for (; *s; s++) {
    if (*s == '"') fputc('"', f);
    fputc(*s, f);
  }
  fputc('"', f);
}

/* Whether a field of the header line is `name` (as --xy reads names: header_name). */
static int header_has(const char *header, const char *name, char *buf, size_t cap) {
  const char *b;
  for (const char *f = header; f && (b = header_name(f, buf, cap)); f = field_end(f))
    if (!strcmp(b, name)) return 1;
  return 0;
}

/* The header with the appended columns: `feature` and each --field, each under its own
 * name, or prefixed with feature_ (again while still taken) when the input's header or an
 * earlier appended column has it: --field name beside a points file with its own name
 * column gives feature_name, so no two output columns share a name. */
static int write_header(FILE *out, const char *line, const char *const *fields, int n_fields) {
  size_t cap = strlen(line) + 1;
  int n = n_fields + 1, rc = CLI_OK;
  char *buf = malloc(cap), **name = calloc((size_t)n, sizeof *name);
  fputs(line, out);
  for (int k = 0; buf && name && k < n && !rc; k++) {
    const char *want = k ? fields[k - 1] : "feature";
    size_t pre = 0, len = strlen(want);
    for (;;) {
      char *c = malloc(pre * 8 + len + 1);
      if (!c) {
        rc = CLI_INTERNAL;
        break;
      }
      for (size_t i = 0; i < pre; i++) memcpy(c + 8 * i, "feature_", 8);
      memcpy(c + 8 * pre, want, len + 1);
      int taken = header_has(line, c, buf, cap);
      for (int i = 0; i < k && !taken; i++) taken = !strcmp(name[i], c);
      if (!taken) {
        name[k] = c;
        break;
      }
      free(c);
      pre++;
    }
    if (!rc) {
      fputc(',', out);
      put_csv(out, name[k]);
    }
  }
  if (!buf || !name) rc = CLI_INTERNAL;
  for (int k = 0; name && k < n; k++) free(name[k]);
  free(name);
  free(buf);
  fputc('\n', out);
  return rc;
}

/* ---- progress --------------------------------------------------------------------------- */

static void progress(int on, long done, long total, size_t rows) {
  if (!on || total <= 0) return;
  int pct = (int)(100.0 * (double)done / (double)total);
  if (pct > 100) pct = 100;
  char bar[41];
  int k = pct * 40 / 100;
  for (int i = 0; i < 40; i++) bar[i] = i < k ? '#' : '.';
  bar[40] = '\0';
  fprintf(stderr, "\r[%s] %3d%% %zu points", bar, pct, rows);
}

/* ---- join ------------------------------------------------------------------------------- */

typedef struct join {
  const char *pts_path;
  qk_region_t *r;
  qk_boundary_t rule;
  int all;
  unsigned threads;
  const char **fields;
  int n_fields;
  FILE *out;
  /* the chunk */
  char **lines;
  qk_point_t *p;
  uint32_t *feat;
  size_t n;
  int dry; /* a checking pass: read and parse every line, write nothing */
} join_t;

static void write_row(join_t *j, const char *line, uint32_t f) {
  fputs(line, j->out);
  fprintf(j->out, ",%ld", f == QK_NONE ? -1L : (long)f);
  for (int k = 0; k < j->n_fields; k++) {
    fputc(',', j->out);
    const char *v = f == QK_NONE ? NULL : qk_region_property(j->r, f, j->fields[k]);
    if (v) put_csv(j->out, v);
  }
  fputc('\n', j->out);
}

static int flush_chunk(join_t *j) {
  if (!j->n) return CLI_OK;
  if (!j->all) {
    qk_status_t st = qk_region_locate_batch(j->r, j->p, j->n, j->rule, j->threads, j->feat);
    if (st) return cli_status("join", "locate", st);
    for (size_t i = 0; i < j->n; i++) write_row(j, j->lines[i], j->feat[i]);
  } else {
    uint32_t buf[64];
    for (size_t i = 0; i < j->n; i++) {
      size_t n;
      qk_status_t st = qk_region_locate_all(j->r, j->p[i], j->rule, buf, 64, &n);
      if (st) return cli_status("join", "locate", st);
      uint32_t *many = buf;
      if (n > 64) {
        many = malloc(n * sizeof *many);
        if (!many) return CLI_INTERNAL;
        st = qk_region_locate_all(j->r, j->p[i], j->rule, many, n, &n);
        if (st) {
          free(many);
          return cli_status("join", "locate", st);
        }
      }
      if (n == 0) write_row(j, j->lines[i], QK_NONE);
      for (size_t k = 0; k < n; k++) write_row(j, j->lines[i], many[k]);
      if (many != buf) free(many);
    }
  }
  for (size_t i = 0; i < j->n; i++) free(j->lines[i]);
  j->n = 0;
  return ferror(j->out) ? CLI_INTERNAL : CLI_OK;
}

static void join_usage(FILE *f) {
  fprintf(f, "usage: quadkit join REGIONS POINTS.csv [--field NAME]... [--all]\n"
             "                    [--boundary semi-open|closed|open] [--planar] [--xy X,Y]\n"
             "                    [--threads N] [-o FILE]\n"
             "\n"
             "For each point (x, y; longitude, latitude unless --planar) the feature of REGIONS\n"
             "(GeoJSON, or any OGR format when built with GDAL) that holds it. Writes CSV: the\n"
             "point's line as read, then `feature` (0-based feature index, -1 for none) and the\n"
             "requested properties (a name no feature has is an error). --all writes one row per\n"
             "containing feature (a point in none gets one row with -1). --xy picks the\n"
             "coordinate columns by header name or 1-based number (default: the first two).\n"
             "A header line (x and y fields not numbers) is copied with the new column names\n"
             "appended, each prefixed feature_ (again while still taken) when the header or an\n"
             "earlier new column has it (--field name beside a name column: feature_name);\n"
             "then every row must have as many fields as the header.\n"
             "A bad line is an error before any row is written (-o FILE is replaced\n"
             "only on success; on standard output, a device or a FIFO a POINTS file is\n"
             "checked whole first, while points from a pipe are written as read).\n"
             "--threads N answers on N threads (default 1; 0: one per core; at most 256).\n");
}

static int join_stream(join_t *j, FILE *in, xy_spec_t *xy, int progress_on, long total) {
  cli_lines_t rd;
  cli_lines_init(&rd, in);
  long len;
  long lineno = 0;
  int seen = 0, rc = CLI_OK;
  int width = 0;  /* the header's number of fields (0: no header), which every row must have */
  long hline = 0; /* the header's line */
  /* The x and y fields, as long as the line (a field cut short could turn
   * '0.5   <300 spaces>junk' into a number). */
  char *fx = NULL, *fy = NULL;
  size_t fcap = 0;
  const char *bad = NULL;
  char xname[256] = "", yname[256] = ""; /* the header's names of the x and y fields */
  /* A record is a line, or several when a quoted field holds line breaks: messages name
   * the physical line where it starts. */
  while ((len = cli_read_record(&rd, &bad)) >= 0) {
    char *line = rd.line;
    lineno = (long)rd.first;
    if (bad) { /* the input ends inside a quoted field: name it, whatever its column */
      int nf = csv_field(line, -1, NULL, 0, &bad);
      field_error(j->pts_path, line, nf < 0 ? -nf : nf, lineno, 0,
                  "unterminated quoted field (it runs to the end of the file)");
      rc = CLI_BAD_INPUT;
      break;
    }
    if ((size_t)len + 1 > fcap) {
      char *nx = realloc(fx, (size_t)len + 1), *ny = nx ? realloc(fy, (size_t)len + 1) : NULL;
      if (nx) fx = nx;
      if (ny) fy = ny;
      if (!nx || !ny) {
        rc = CLI_INTERNAL;
        break;
      }
      fcap = (size_t)len + 1;
    }
    size_t bom = 0;
    if (lineno == 1 && (unsigned char)line[0] == 0xEF && (unsigned char)line[1] == 0xBB &&
        (unsigned char)line[2] == 0xBF)
      memmove(line, line + 3, (size_t)len - 2), bom = 3;
    const char *q = line;
    while (*q == ' ' || *q == '\t') q++;
    if (!*q) continue;
    if (!seen) {
      seen = 1;
      double v;
      int named = xy->col[0] < 0 || xy->col[1] < 0;
      int xc = xy->col[0] >= 0 ? xy->col[0] : 0, yc = xy->col[1] >= 0 ? xy->col[1] : 1;
      /* a header: neither x nor y is a number (as the library's reader decides); a
       * malformed quote there is an error, not a header */
      const char *why = NULL;
      int rx = named ? 1 : csv_field(line, xc, fx, fcap, &why);
      int ry = named || rx < 0 ? 1 : csv_field(line, yc, fy, fcap, &why);
      if (rx < 0 || ry < 0) {
        field_error(j->pts_path, line, -(rx < 0 ? rx : ry), lineno, bom, why);
        rc = CLI_BAD_INPUT;
        break;
      }
      int header = named || ((rx != 1 || !number(fx, &v)) && (ry != 1 || !number(fy, &v)));
      if (header) {
        if (resolve_xy("join", j->pts_path, line, lineno, bom, xy)) {
          rc = CLI_BAD_INPUT;
          break;
        }
        width = csv_field(line, -1, NULL, 0, &why), hline = lineno;
        csv_field(line, xy->col[0], xname, sizeof xname, NULL); /* (for messages) */
        csv_field(line, xy->col[1], yname, sizeof yname, NULL);
        for (char *nm = xname; nm; nm = nm == xname ? yname : NULL) { /* (blanks cut) */
          const char *t = trim(nm);
          memmove(nm, t, strlen(t) + 1);
        }
        if (width < 0) {
          field_error(j->pts_path, line, -width, lineno, bom, why);
          rc = CLI_BAD_INPUT;
          break;
        }
        if (j->dry) continue;
        if ((rc = write_header(j->out, line, j->fields, j->n_fields))) break;
        continue;
      }
    }
    double x, y;
    const char *why = NULL;
    int hx = csv_field(line, xy->col[0], fx, fcap, &why);
    int hy = hx < 0 ? 0 : csv_field(line, xy->col[1], fy, fcap, &why);
    if (hx < 0 || hy < 0) {
      field_error(j->pts_path, line, -(hx < 0 ? hx : hy), lineno, bom, why);
      rc = CLI_BAD_INPUT;
      break;
    }
    if (!hx || !hy) {
      cli_msg("quadkit join: %s:%ld: no field %d (need x in field %d, y in field %d)\n",
              j->pts_path, lineno, (!hx ? xy->col[0] : xy->col[1]) + 1, xy->col[0] + 1,
              xy->col[1] + 1);
      rc = CLI_BAD_INPUT;
      break;
    }
    const int gx = number(fx, &x), gy = gx == 1 ? number(fy, &y) : 1;
    if (gx != 1 || gy != 1 || !isfinite(x) || !isfinite(y)) {
      const int bx = gx != 1 || !isfinite(x); /* (x is named first, as before) */
      const char *bad = bx ? fx : fy;
      int col = bad == fx ? xy->col[0] : xy->col[1];
      const char *name = bad == fx ? xname : yname;
      /* FILE:LINE:COLUMN and the header's name of the field, as the other commands'
       * reader says it (it said "FILE:LINE: field 2", leaving the column to count). */
      unsigned long fl, fc;
      field_at(line, col, (unsigned long)lineno, bom, &fl, &fc);
      char nbuf[52], vbuf[44];
      cli_msg("quadkit join: %s:%lu:%lu: field %d%s%s%s is %s: '%s'\n", j->pts_path, fl, fc,
              col + 1, name[0] ? " (" : "", cli_cut(name, 47, nbuf), name[0] ? ")" : "",
              (bx ? gx : gy) == -2 ? "below the smallest double (it would read as 0)"
                                   : "not a finite number",
              cli_cut(bad, 40, vbuf));
      rc = CLI_BAD_INPUT;
      break;
    }
    int nf = width ? csv_field(line, -1, NULL, 0, &why) : 0;
    if (nf < 0) {
      field_error(j->pts_path, line, -nf, lineno, bom, why);
      rc = CLI_BAD_INPUT;
      break;
    }
    if (nf != width) {
      /* the row is copied as read under the header's names: a wider or narrower one would
       * put `feature` and the properties under other columns */
      cli_msg("quadkit join: %s:%ld: %d fields where the header (line %ld) has %d\n", j->pts_path,
              lineno, nf, hline, width);
      rc = CLI_BAD_INPUT;
      break;
    }
    if (j->dry) continue;
    char *copy = malloc((size_t)len + 1);
    if (!copy) {
      rc = CLI_INTERNAL;
      break;
    }
    memcpy(copy, line, (size_t)len + 1);
    j->lines[j->n] = copy;
    j->p[j->n] = (qk_point_t){x, y};
    if (++j->n == CHUNK) {
      if ((rc = flush_chunk(j))) break;
      progress(progress_on, ftell(in), total, (size_t)lineno);
    }
  }
  if (!rc) rc = cli_lines_status("join", j->pts_path, &rd, len, bad, 1);
  if (!rc) rc = flush_chunk(j);
  for (size_t i = 0; i < j->n; i++) free(j->lines[i]);
  j->n = 0;
  cli_lines_free(&rd);
  free(fx);
  free(fy);
  if (progress_on && !j->dry) {
    progress(progress_on, total, total, (size_t)lineno);
    fputc('\n', stderr);
  }
  return rc;
}

/* A --field that no feature has is a typo, not an empty column: refuse it. */
static int check_fields(const char *path, const qk_region_t *r, const char **fields, int nf) {
  size_t nfeat = qk_region_feature_count(r);
  for (int k = 0; k < nf; k++) {
    size_t f = 0;
    while (f < nfeat && !qk_region_property(r, (uint32_t)f, fields[k])) f++;
    if (f == nfeat) {
      cli_error("join", "%s: --field %s: no feature of the %zu has that property", path, fields[k],
                nfeat);
      return CLI_BAD_INPUT;
    }
  }
  return CLI_OK;
}

int cmd_join(int argc, char **argv) {
  const char *pos[2] = {NULL, NULL}, *outp = "-", *xys = NULL;
  int npos = 0, planar = 0, all = 0;
  qk_boundary_t rule = QK_BOUNDARY_SEMI_OPEN;
  unsigned long threads = 1;
  const char **fields = calloc((size_t)argc + 1, sizeof *fields);
  int nf = 0, rc = CLI_OK;
  if (!fields) return CLI_INTERNAL;
  for (int i = 1; i < argc && !rc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
      join_usage(stdout);
      free(fields);
      return CLI_OK;
    } else if (!strcmp(a, "--field")) {
      if (i + 1 >= argc)
        cli_error("join", "--field needs a name"), rc = CLI_USAGE;
      else
        fields[nf++] = argv[++i];
    } else if (!strcmp(a, "--all"))
      all = 1;
    else if (!strcmp(a, "--planar"))
      planar = 1;
    else if (!strcmp(a, "--boundary")) {
      if (parse_boundary("join", i + 1 < argc ? argv[++i] : NULL, &rule)) rc = CLI_USAGE;
    } else if (!strcmp(a, "--xy")) {
      xys = i + 1 < argc ? argv[++i] : "";
    } else if (!strcmp(a, "--threads")) {
      if (cli_parse_u32("join", "--threads", i + 1 < argc ? argv[++i] : NULL, 0, 256, &threads))
        rc = CLI_USAGE;
    } else if (!strcmp(a, "-o")) {
      if (i + 1 >= argc)
        cli_error("join", "-o needs a file"), rc = CLI_USAGE;
      else
        outp = argv[++i];
    } else if (a[0] == '-' && a[1]) {
      cli_error("join", "unknown option '%s' (see quadkit join --help)", a);
      rc = CLI_USAGE;
    } else if (npos < 2)
      pos[npos++] = a;
    else {
      cli_error("join", "too many arguments ('%s')", a);
      rc = CLI_USAGE;
    }
  }
  xy_spec_t xy = {{"1", "2"}, {0, 1}};
  if (!rc && xys && parse_xy("join", xys, &xy)) rc = CLI_USAGE;
  if (!rc && npos != 2) {
    cli_error("join", "needs REGIONS and POINTS.csv (see quadkit join --help)");
    rc = CLI_USAGE;
  }
  if (rc) {
    free(fields);
    return rc;
  }
  if ((rc = cli_inputs_once("join", pos, 2))) {
    free(fields);
    return rc;
  }
  FILE *in = cli_input_open("join", pos[1]); /* ("-": standard input) */
  if (!in) {
    free(fields);
    return CLI_BAD_INPUT;
  }
  /* The output is opened before the layer is read: one that cannot be written, or that
   * is an input (`-o POINTS`, the points' pipe: `-o /dev/stdin`), fails before any work. */
  cli_note_input(pos[0]);
  cli_out_t o = {0};
  rc = cli_out_open("join", outp, &o);
  int said = rc != CLI_OK; /* (cli_out_open or read_layer printed why, out of memory included) */
  qk_region_t *r = NULL;
  if (!rc) {
    rc = read_layer("join", pos[0], planar, &r);
    said = rc != CLI_OK;
  }
  if (!rc) {
    /* A layer without a single polygon puts every point outside: no answer, and most
     * likely the wrong file (a points CSV that GDAL reads as a table, the arguments
     * swapped, a layer of lines). Said, not answered with a column of -1. */
    qk_region_stats_t rs;
    qk_region_stats(r, &rs);
    if (rs.rings == 0) {
      cli_error("join",
                "%s: no polygons to join against (%zu features, %zu skipped geometries: "
                "points, lines, empty or null)",
                pos[0], rs.features, rs.skipped);
      rc = CLI_BAD_INPUT;
    }
  }
  if (!rc) rc = check_fields(pos[0], r, fields, nf);
  join_t j = {cli_input_name(pos[1]),
              r,
              rule,
              all,
              (unsigned)threads,
              fields,
              nf,
              NULL,
              NULL,
              NULL,
              NULL,
              0,
              0};
  int wfail = 0; /* the output failed (cli_out_close said so) */
  if (!rc) {
    j.out = o.f;
    j.lines = malloc(CHUNK * sizeof *j.lines);
    j.p = malloc(CHUNK * sizeof *j.p);
    j.feat = malloc(CHUNK * sizeof *j.feat);
    if (!j.lines || !j.p || !j.feat) rc = CLI_INTERNAL;
    struct stat sb;
    int regular = !fstat(fileno(in), &sb) && S_ISREG(sb.st_mode);
    /* (where reading starts: standard input may be a file already partly read) */
    off_t start = regular ? ftello(in) : 0;
    if (start < 0) start = 0, regular = 0;
    long total = regular ? (long)sb.st_size : 0; /* (the progress bar: offsets in the file) */
    /* Standard output, a device or a FIFO cannot be taken back: a regular file of points
     * is read once without writing, so that a bad line stops the command before its
     * first row (a FIFO as -o got 65,537 lines, then the error). (-o FILE is written to
     * a temporary and renamed only on success; from a pipe the rows are written as they
     * come.) */
    if (!rc && (o.f == stdout || o.direct) && regular) {
      xy_spec_t xy_check = xy;
      j.dry = 1;
      rc = join_stream(&j, in, &xy_check, 0, total);
      j.dry = 0;
      if (!rc && fseeko(in, start, SEEK_SET) != 0) {
        cli_error("join", "%s: cannot read it again: %s", j.pts_path, strerror(errno));
        rc = CLI_BAD_INPUT;
      }
    }
    if (!rc) rc = join_stream(&j, in, &xy, isatty(2) && total > 0, total);
    wfail = o.f && ferror(o.f);
  }
  if (o.f) {
    int rc2 = cli_out_close("join", &o, rc == CLI_OK); /* (says why a write failed) */
    if (rc2) wfail = 1;
    if (!rc) rc = rc2;
  }
  if (rc == CLI_INTERNAL && !wfail && !said) cli_error("join", "out of memory");
  free(j.lines);
  free(j.p);
  free(j.feat);
  cli_input_close(in);
  qk_region_free(r);
  free(fields);
  return rc;
}

/* ---- regions ------------------------------------------------------------------------------ */

int cmd_regions(int argc, char **argv) {
  const char *path = NULL, *svg = NULL;
  int planar = 0, rc = CLI_OK;
  for (int i = 1; i < argc && !rc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
      printf("usage: quadkit regions REGIONS [--stats] [--svg FILE] [--planar]\n\n"
             "Reads a polygon layer and prints its statistics as JSON (features, rings,\n"
             "vertices, holes, self-intersecting rings, skipped geometries, index leaves,\n"
             "depth, bytes, build seconds); --svg draws the features and index cells.\n");
      return CLI_OK;
    } else if (!strcmp(a, "--stats")) {
    } else if (!strcmp(a, "--planar"))
      planar = 1;
    else if (!strcmp(a, "--svg")) {
      if (i + 1 >= argc)
        cli_error("regions", "--svg needs a file"), rc = CLI_USAGE;
      else
        svg = argv[++i];
    } else if (a[0] == '-' && a[1]) {
      cli_error("regions", "unknown option '%s' (see quadkit regions --help)", a);
      rc = CLI_USAGE;
    } else if (!path)
      path = a;
    else
      cli_error("regions", "too many arguments ('%s')", a), rc = CLI_USAGE;
  }
  if (!rc && !path) cli_error("regions", "needs REGIONS"), rc = CLI_USAGE;
  if (rc) return rc;
  /* Standard output (the statistics) and the picture's file first, before the layer is
   * read: one that cannot be written, or that is the layer itself (a pipe: `regions
   * /dev/stdin --svg /dev/stdin`) or standard output again (`--svg /dev/stdout`), fails
   * before any work. */
  cli_note_input(path);
  cli_out_t so, o;
  if ((rc = cli_out_open("regions", "-", &so)) ||
      (svg && (rc = cli_out_open("regions", svg, &o)))) {
    cli_out_close("regions", &so, 0);
    return rc;
  }
  qk_region_t *r = NULL;
  rc = read_layer("regions", path, planar, &r);
  if (!rc && svg) {
    qk_status_t st = qk_region_write_svg(r, o.f, 1200);
    if (st == QK_OK && (fflush(o.f) != 0 || ferror(o.f))) st = QK_ERR_IO;
    if (st == QK_ERR_IO && ferror(o.f))
      rc = CLI_INTERNAL; /* (said when the picture is closed) */
    else if (st)
      rc = cli_status("regions", svg, st);
  }
  /* The statistics once the picture is written (a failed write printed them too), and
   * out before the picture is renamed into place: when standard output fails, the
   * picture is not left behind. */
  if (!rc) {
    qk_region_stats_t s;
    qk_region_stats(r, &s);
    printf("{\"features\": %zu, \"rings\": %zu, \"vertices\": %zu, \"holes\": %zu, "
           "\"self_intersecting_rings\": %zu, \"skipped_geometries\": %zu, \"edge_pieces\": %zu, "
           "\"leaves\": %zu, \"leaf_edges\": %zu, \"depth\": %u, \"bytes\": %zu, "
           "\"build_seconds\": %.6f, \"mode\": \"%s\", \"bbox\": [%.17g, %.17g, %.17g, %.17g]}\n",
           s.features, s.rings, s.vertices, s.holes, s.self_intersecting, s.skipped, s.edges,
           s.leaves, s.leaf_edges, s.depth, s.bytes, s.build_seconds,
           s.planar ? "planar" : "lonlat", s.box.xmin + 0.0, s.box.ymin + 0.0, s.box.xmax + 0.0,
           s.box.ymax + 0.0); /* (-0 as 0) */
  }
  int rc2 = cli_out_close("regions", &so, rc == CLI_OK);
  if (!rc) rc = rc2;
  if (svg) {
    rc2 = cli_out_close("regions", &o, rc == CLI_OK);
    if (!rc) rc = rc2;
  }
  qk_region_free(r);
  return rc;
}
