/* CSV input of the command-line tool: the library's reader, its errors printed with
 * file, line and column, and the rows' text kept for --keep. */
#define _POSIX_C_SOURCE 200809L /* fmemopen, fseeko, ftello */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#include "cli.h"

void cli_rows_free(cli_rows_t *r) {
  if (!r) return;
  for (size_t i = 0; r->text && i < r->n; i++) free(r->text[i]);
  free(r->text);
  free(r->lineno);
  free(r->header);
  int keep = r->keep_text;
  memset(r, 0, sizeof *r);
  r->keep_text = keep;
}

/* The quote state of CSV text after s[0, n), from state q: 0 at a field's start, 1 in an
 * unquoted field or after a closing quote, 2 inside quotes, 3 just after a quote inside
 * quotes (a closing one, or the first of ""). Only a quote at a field's start (blanks
 * before it allowed) opens a quoted field, as the library's reader says. */
static int quote_state(int q, const char *s, size_t n, size_t *commas) {
  for (size_t i = 0; i < n; i++) {
    char c = s[i];
    if (q == 0)
      q = c == '"' ? 2 : c == ',' || c == ' ' || c == '\t' ? 0 : 1;
    else if (q == 1)
      q = c == ',' ? 0 : 1;
    else if (q == 2)
      q = c == '"' ? 3 : 2;
    else
      q = c == '"' ? 2 : c == ',' ? 0 : 1;
    if (q == 0 && c == ',' && commas) ++*commas;
  }
  return q;
}

/* Fields of a CSV record (quotes respected). */
static size_t count_fields(const char *s) {
  size_t n = 1;
  quote_state(0, s, strlen(s), &n);
  return n;
}

enum { CHUNK = 1 << 16 };

/* The message for a line past CLI_MAX_LINE (its number written out: the limit a user
 * meets is the one to state). */
#define TOO_LONG "line longer than 1048576 bytes (1 MiB), the limit for a line of text input"
_Static_assert(CLI_MAX_LINE == 1048576, "TOO_LONG states the limit");

void cli_lines_init(cli_lines_t *r, FILE *f) {
  memset(r, 0, sizeof *r);
  r->f = f;
}

void cli_lines_free(cli_lines_t *r) {
  free(r->chunk);
  free(r->line);
  free(r->part);
  r->chunk = r->line = r->part = NULL;
  r->cap = r->pcap = 0;
}

/* Room for `need` bytes in *buf (*cap its size), grown by doubling. */
static int room(char **buf, size_t *cap, size_t need) {
  if (need <= *cap) return 0;
  size_t nc = *cap ? *cap : 256;
  while (nc < need) nc *= 2;
  char *p = realloc(*buf, nc);
  if (!p) return -1;
  *buf = p, *cap = nc;
  return 0;
}

/* One physical line into *buf, as cli_read_line says. Each piece of a chunk is checked
 * before it is kept: a NUL byte or a line past the limit stops the reader within one
 * chunk (64 KiB) of it, whatever follows (getline, used before, took a line of any
 * length into memory first: /dev/zero grew the process to gigabytes before "out of
 * memory"). */
static long line_into(cli_lines_t *r, char **buf, size_t *cap, const char **why) {
  if (!r->chunk && !(r->chunk = malloc(CHUNK))) return -3;
  size_t n = 0;
  int open = 0;
  r->col = 0;
  for (;;) {
    if (r->cpos == r->clen) {
      if (r->eof) break;
      r->clen = fread(r->chunk, 1, CHUNK, r->f);
      r->cpos = 0;
      if (r->clen < CHUNK) r->eof = 1; /* the end, or a read error (ferror tells) */
      if (r->tee && r->clen) {
        if (r->tee_len + r->clen > CLI_STREAM_MAX) {
          *why = "input from a pipe or device longer than 2147483647 bytes, the limit for a "
                 "stream (a regular file has none)";
          return -4;
        }
        if (room(&r->tee_buf, &r->tee_cap, r->tee_len + r->clen)) return -3;
        memcpy(r->tee_buf + r->tee_len, r->chunk, r->clen);
        r->tee_len += r->clen;
      }
      if (!r->clen) break;
    }
    const char *s = r->chunk + r->cpos;
    size_t avail = r->clen - r->cpos;
    const char *nl = memchr(s, '\n', avail);
    size_t take = nl ? (size_t)(nl - s) : avail;
    if (!open) open = 1, r->phys++;
    if (r->phys == 1 && n == 0 && s == r->chunk && avail >= 2 &&
        ((s[0] == '\xFF' && s[1] == '\xFE') || (s[0] == '\xFE' && s[1] == '\xFF'))) {
      /* A UTF-16 byte order mark (what Windows tools write as "Unicode"): every other
       * byte of ASCII text is a NUL there, which "binary data" would not explain. */
      r->col = 1;
      *why = "UTF-16 text (a UTF-16 byte order mark): text input must be UTF-8 or ASCII; "
             "convert it first (iconv -f UTF-16 -t UTF-8)";
      return -2;
    }
    const char *z = memchr(s, '\0', take);
    if (z) {
      r->col = (unsigned long)(n + (size_t)(z - s)) + 1;
      *why = "binary data (NUL byte) in a text file";
      return -2;
    }
    /* (a CR ending the line so far is not counted: the CR of a CR LF line end, or, when
     * no LF follows it, counted with the bytes that do) */
    const char last = take ? s[take - 1] : n ? (*buf)[n - 1] : '\0';
    if (n + take - (last == '\r') > CLI_MAX_LINE) {
      /* A CR alone inside it is the likelier cause (a file with CR line ends reads as
       * one line): say that, where it is. */
      size_t lim = nl && take && s[take - 1] == '\r' ? take - 1 : take;
      const char *cr = memchr(*buf ? *buf : "", '\r', n);
      const char *cr2 = cr ? NULL : memchr(s, '\r', lim);
      if (cr || cr2) {
        r->col = (unsigned long)(cr ? (size_t)(cr - *buf) : n + (size_t)(cr2 - s)) + 1;
        *why = CLI_LONE_CR;
      } else {
        *why = TOO_LONG;
      }
      return -2;
    }
    if (room(buf, cap, n + take + 1)) return -3;
    memcpy(*buf + n, s, take);
    n += take;
    r->cpos += take + (nl != NULL);
    if (nl) break;
  }
  if (!open) return -1;
  (*buf)[n] = '\0';
  return (long)n;
}

long cli_read_line(cli_lines_t *r, const char **why) {
  *why = NULL;
  return line_into(r, &r->line, &r->cap, why);
}

long cli_read_record(cli_lines_t *r, const char **why) {
  *why = NULL;
  long got = line_into(r, &r->line, &r->cap, why);
  if (got < 0) return got;
  r->first = r->phys;
  size_t n = (size_t)got;
  if (cli_cut_line_end(r->line, &n)) {
    r->col = (unsigned long)((const char *)memchr(r->line, '\r', n) - r->line) + 1;
    *why = CLI_LONE_CR;
    return -2;
  }
  size_t bom = r->phys == 1 && n >= 3 && !memcmp(r->line, "\xEF\xBB\xBF", 3) ? 3 : 0;
  int q = quote_state(0, r->line + bom, n - bom, NULL);
  /* Inside quotes at the line's end: the record goes on, with a line feed in the field. */
  while (q == 2) {
    got = line_into(r, &r->part, &r->pcap, why);
    if (got == -1) {
      /* the input ends inside quotes: the record is returned, flagged (the rows after
       * the quote would be lost without a word) */
      *why = "unterminated quoted field (it runs to the end of the file)";
      break;
    }
    if (got < 0) return got;
    size_t c = (size_t)got;
    if (cli_cut_line_end(r->part, &c)) {
      r->col = (unsigned long)((const char *)memchr(r->part, '\r', c) - r->part) + 1;
      *why = CLI_LONE_CR;
      return -2;
    }
    if (room(&r->line, &r->cap, n + c + 2)) return -3;
    r->line[n++] = '\n';
    memcpy(r->line + n, r->part, c);
    q = quote_state(q, r->line + n, c, NULL);
    n += c;
  }
  r->line[n] = '\0';
  return (long)n;
}

static char *dup_text(const char *s, size_t len) {
  char *p = malloc(len + 1);
  if (p) memcpy(p, s, len), p[len] = '\0';
  return p;
}

/* The reader's row callback: line numbers always, the text when kept. */
static qk_status_t on_row(void *ud, size_t row, unsigned long lineno, const char *line,
                          size_t len) {
  cli_rows_t *r = ud;
  size_t nf = r->keep_text ? count_fields(line) : 0;
  if (nf > r->width) r->width = nf;
  if (row == SIZE_MAX) {
    if (r->keep_text && !(r->header = dup_text(line, len))) return QK_ERR_NOMEM;
    return QK_OK;
  }
  if (r->n == r->cap) {
    size_t nc = r->cap ? 2 * r->cap : 1024;
    unsigned long *nl = realloc(r->lineno, nc * sizeof *nl);
    if (!nl) return QK_ERR_NOMEM;
    r->lineno = nl;
    if (r->keep_text) {
      char **nt = realloc(r->text, nc * sizeof *nt);
      if (!nt) return QK_ERR_NOMEM;
      r->text = nt;
    }
    r->cap = nc;
  }
  if (r->keep_text && !(r->text[r->n] = dup_text(line, len))) return QK_ERR_NOMEM;
  r->lineno[r->n++] = lineno;
  return QK_OK;
}

/* Print the reader's error and map it to an exit code. */
static int read_error(const char *path, qk_status_t st, const qk_error_t *e) {
  if (e->line && e->column)
    cli_msg("quadkit: %s:%lu:%lu: %s\n", path, e->line, e->column, e->message);
  else if (e->line)
    cli_msg("quadkit: %s:%lu: %s\n", path, e->line, e->message);
  else
    cli_msg("quadkit: %s: %s\n", path, e->message[0] ? e->message : qk_strerror(st));
  return st == QK_ERR_NOMEM ? CLI_INTERNAL : CLI_BAD_INPUT;
}

int cli_lines_status(const char *cmd, const char *path, const cli_lines_t *r, long got,
                     const char *why, int columns) {
  const char *sp = cmd ? " " : "", *c = cmd ? cmd : "";
  if (got == -2 && r->col && columns) {
    cli_msg("quadkit%s%s: %s:%lu:%lu: %s\n", sp, c, path, r->phys, r->col, why);
    return CLI_BAD_INPUT;
  }
  if (got == -2) {
    cli_msg("quadkit%s%s: %s:%lu: %s\n", sp, c, path, r->phys, why);
    return CLI_BAD_INPUT;
  }
  if (got == -3) {
    cli_msg("quadkit%s%s: %s:%lu: out of memory reading the line\n", sp, c, path, r->phys);
    return CLI_INTERNAL;
  }
  if (got == -4) { /* the input as a whole, no line of it */
    cli_msg("quadkit%s%s: %s: %s\n", sp, c, path, why);
    return CLI_BAD_INPUT;
  }
  if (ferror(r->f)) {
    cli_msg("quadkit%s%s: %s: read error\n", sp, c, path);
    return CLI_BAD_INPUT;
  }
  return CLI_OK;
}

/* Screen an input with the tool's line reader before a library reader sees it (cli.h):
 * the CSV reader takes a line of any length into memory before it checks it (a library matter,
 * include/quadkit/io.h), so /dev/zero or a file without line breaks grew the process
 * until "out of memory". A NUL byte or a line past CLI_MAX_LINE is refused here, within
 * 64 KiB of it. A regular file is read again from where the screen began (the screen keeps
 * nothing: a pass over text in the page cache, a few per cent of the read): not from byte
 * 0, since standard input may be a file already partly read (`{ read -r t; quadkit mesh -
 * ...; } < f` was screened from the second line and parsed from the first). A pipe, FIFO or
 * device cannot be read again, so its bytes as read are kept and *f becomes a stream over
 * them (*copy, which the caller frees once the library is done). Returns an exit code. */
int cli_screen_input(const char *cmd, const char *path, int columns, FILE **f, char **copy) {
  const char *sp = cmd ? " " : "", *c = cmd ? cmd : "";
  struct stat st;
  int regular = !fstat(fileno(*f), &st) && S_ISREG(st.st_mode);
  const off_t start = regular ? ftello(*f) : 0;
  if (start < 0) {
    cli_msg("quadkit%s%s: %s: cannot tell where reading starts: %s\n", sp, c, path,
            strerror(errno));
    return CLI_BAD_INPUT;
  }
  cli_lines_t r;
  cli_lines_init(&r, *f);
  r.tee = !regular;
  const char *why;
  long got;
  while ((got = cli_read_line(&r, &why)) >= 0) continue;
  int rc = cli_lines_status(cmd, path, &r, got, why, columns);
  cli_lines_free(&r);
  if (!rc && regular && fseeko(*f, start, SEEK_SET) != 0) {
    cli_msg("quadkit%s%s: %s: cannot read it again: %s\n", sp, c, path, strerror(errno));
    rc = CLI_BAD_INPUT;
  }
  if (!rc && !regular && r.tee_len) { /* (empty: *f is at its end, as the copy would be) */
    FILE *m = fmemopen(r.tee_buf, r.tee_len, "r");
    if (!m) {
      cli_msg("quadkit%s%s: %s: cannot keep it in memory: %s\n", sp, c, path, strerror(errno));
      rc = CLI_INTERNAL;
    } else {
      if (*f != stdin) fclose(*f); /* (stdin is the caller's to keep) */
      *f = m;
      *copy = r.tee_buf;
      return CLI_OK;
    }
  }
  free(r.tee_buf);
  return rc;
}

const char *cli_input_name(const char *path) { return strcmp(path, "-") ? path : "<stdin>"; }

/* Where standard input stood when "-" was first opened (-1: not yet, or not a regular
 * file): each later "-" reads it again from there. */
static off_t stdin_start = -1;

FILE *cli_input_open(const char *cmd, const char *path) {
  if (strcmp(path, "-")) return cli_open_input(cmd, path);
  const char *sp = cmd ? " " : "", *c = cmd ? cmd : "";
  static int opened;
  struct stat st;
  if (fstat(STDIN_FILENO, &st) != 0) {
    cli_msg("quadkit%s%s: <stdin>: cannot read: %s\n", sp, c, strerror(errno));
    return NULL;
  }
  if (S_ISDIR(st.st_mode)) {
    cli_msg("quadkit%s%s: <stdin>: cannot read: it is a directory\n", sp, c);
    return NULL;
  }
  cli_note_input("-"); /* (an output naming it, or its pipe, is refused) */
  if (S_ISREG(st.st_mode)) {
    if (!opened) {
      stdin_start = ftello(stdin);
    } else if (stdin_start >= 0 && fseeko(stdin, stdin_start, SEEK_SET) != 0) {
      cli_msg("quadkit%s%s: <stdin>: cannot read it again: %s\n", sp, c, strerror(errno));
      return NULL;
    }
  }
  opened = 1;
  clearerr(stdin);
  return stdin;
}

void cli_input_close(FILE *f) {
  if (f && f != stdin) fclose(f);
}

/* What an input is when it can be read only once: a pipe or FIFO, a socket, a terminal
 * (NULL otherwise: a regular file or a device read anew at each open). */
static const char *read_once(const char *path, const struct stat *st) {
  if (S_ISFIFO(st->st_mode)) return "pipe or FIFO";
  if (S_ISSOCK(st->st_mode)) return "socket";
  if (!S_ISCHR(st->st_mode)) return NULL;
  int tty;
  if (!strcmp(path, "-")) {
    tty = isatty(STDIN_FILENO);
  } else {
    int fd = open(path, O_RDONLY | O_NOCTTY | O_NONBLOCK);
    tty = fd >= 0 && isatty(fd);
    if (fd >= 0) close(fd);
  }
  return tty ? "terminal" : NULL;
}

int cli_inputs_once(const char *cmd, const char *const *paths, int n) {
  struct stat st[8];
  int have[8];
  for (int i = 0; i < n && i < 8; i++) {
    have[i] = paths[i] &&
              (!strcmp(paths[i], "-") ? fstat(STDIN_FILENO, &st[i]) : stat(paths[i], &st[i])) == 0;
    for (int k = 0; k < i; k++) {
      const char *what;
      if (!have[i] || !have[k] || st[i].st_dev != st[k].st_dev || st[i].st_ino != st[k].st_ino ||
          !(what = read_once(paths[i], &st[i])))
        continue;
      cli_error(cmd,
                "inputs '%s' and '%s' are one %s, which can be read only once (a second "
                "read finds the text gone): save the text to a file and name the file twice",
                paths[k], paths[i], what);
      return CLI_USAGE;
    }
  }
  return CLI_OK;
}

/* Read through the library with `columns` selected, rows collected into *rows. */
static int read_values(const char *path, const char *columns, int required, int cols,
                       cli_rows_t *rows, double **v, size_t *n) {
  cli_rows_t scratch = {0};
  if (!rows) rows = &scratch;
  qk_csv_options_t opt;
  qk_csv_options_init(&opt);
  opt.columns = columns;
  opt.on_row = on_row;
  opt.ud = rows;
  qk_error_t err;
  FILE *f = cli_input_open(NULL, path);
  if (!f) return CLI_BAD_INPUT;
  const char *name = cli_input_name(path);
  char *copy = NULL;
  int rc = cli_screen_input(NULL, name, 1, &f, &copy);
  if (rc) {
    cli_input_close(f);
    return rc;
  }
  qk_status_t st = qk_csv_read_values(f, &opt, (size_t)cols, (size_t)required, NULL, v, n, &err);
  cli_input_close(f);
  free(copy);
  rc = st == QK_OK ? CLI_OK : read_error(name, st, &err);
  if (rc || rows == &scratch) cli_rows_free(rows);
  return rc;
}

int cli_read_table(const char *path, int required, int cols, cli_rows_t *rows, cli_table_t *out) {
  memset(out, 0, sizeof *out);
  out->cols = cols;
  return read_values(path, NULL, required, cols, rows, &out->v, &out->rows);
}

void cli_table_free(cli_table_t *t) {
  free(t->v);
  memset(t, 0, sizeof *t);
}

static int read_points(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                       size_t *n, int need_rows) {
  double *v = NULL;
  *pts = NULL;
  *n = 0;
  int rc = read_values(path, xy, 2, 2, rows, &v, n);
  if (rc) return rc;
  if (*n == 0 && need_rows) {
    cli_msg("quadkit: %s: no data rows\n", cli_input_name(path));
    cli_rows_free(rows);
    return CLI_BAD_INPUT;
  }
  *pts = (qk_point_t *)(void *)v; /* rows of two doubles: the points' layout */
  return CLI_OK;
}

int cli_read_points(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                    size_t *n) {
  return read_points(path, xy, rows, pts, n, 1);
}

int cli_read_queries(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                     size_t *n) {
  return read_points(path, xy, rows, pts, n, 0);
}

void cli_write_fields(FILE *f, const char *text, size_t width, const char *prefix) {
  size_t nf = 0;
  if (text && prefix) {
    /* The header's names, each prefixed (inside the quotes of a quoted name). */
    const char *s = text;
    for (;;) {
      while (*s == ' ' || *s == '\t') s++;
      fputc(',', f);
      int quoted = 0;
      if (*s == '"') {
        fputc(*s++, f);
        quoted = 1;
      }
      fputs(prefix, f);
      while (*s && (quoted || *s != ',')) {
        if (*s == '"') quoted = !quoted;
        fputc(*s++, f);
      }
      nf++;
      if (!*s) break;
      s++;
    }
  } else if (text) {
    fputc(',', f);
    fputs(text, f);
    nf = count_fields(text);
  }
  for (; nf < width; nf++) {
    if (prefix)
      fprintf(f, ",%s%zu", prefix, nf + 1);
    else
      fputc(',', f);
  }
}

int cli_cut_line_end(char *line, size_t *len) {
  size_t n = *len;
  while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r')) line[--n] = '\0';
  *len = n;
  return memchr(line, '\r', n) != NULL;
}
