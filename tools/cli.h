/*
 * Shared plumbing of the `quadkit` command-line tool: exit codes, CSV input, option
 * parsing helpers and the subcommand entry points.
 */
#ifndef QUADKIT_CLI_H
#define QUADKIT_CLI_H

#include <stddef.h>
#include <stdio.h>

#include "quadkit/quadkit.h"

/* Exit codes (documented in the README and in --help). */
enum { CLI_OK = 0, CLI_BAD_INPUT = 1, CLI_USAGE = 2, CLI_INTERNAL = 3 };

/* A numeric CSV table: rows x cols doubles, row-major. A field a row does not have (an
 * optional column) is NAN; nfields[r] says how many the row had (at most cols). */
typedef struct cli_table {
  double *v;
  size_t rows;
  int cols;
  unsigned char *nfields;
} cli_table_t;

/*
 * Read a CSV file: per line, the first `max_fields` comma-separated fields; the first
 * `min_fields` must be present and numeric, the optional ones numeric when present;
 * fields past max_fields are ignored (so names and other columns may follow). A first
 * line whose first field is not a number is a header and skipped. Blank lines are
 * skipped; every other line is a data row and its 0-based index is its id. Coordinates
 * must be finite. On error prints "FILE:LINE: reason" to stderr and returns CLI_BAD_INPUT
 * (CLI_INTERNAL when out of memory); on success CLI_OK. Free with cli_table_free().
 */
int cli_read_csv(const char *path, int min_fields, int max_fields, cli_table_t *out);
void cli_table_free(cli_table_t *t);

/* Read points (first two fields x, y) into a freshly malloc'd array. */
int cli_read_points(const char *path, qk_point_t **pts, size_t *n);

/* Print "quadkit CMD: message" to stderr (printf-style). */
void cli_error(const char *cmd, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* Map a library status to an exit code, printing what failed. */
int cli_status(const char *cmd, const char *what, qk_status_t st);

/* qk_tree_build with an error message that names the file (and, for an extent too large
 * for a double, the values). Returns an exit code. */
int cli_build_tree(const char *cmd, const char *path, const qk_point_t *pts, size_t n,
                   const qk_tree_options_t *opt, qk_tree_t **out);

/* Parse option values; print a usage error and return nonzero when malformed. */
int cli_parse_u32(const char *cmd, const char *opt, const char *s, unsigned long min,
                  unsigned long max, unsigned long *out);
int cli_parse_double(const char *cmd, const char *opt, const char *s, double *out);

/*
 * Output files are written to "PATH.tmp.PID" and renamed on success so that a failed run
 * leaves no half-written file; a symbolic link is written through (its target replaced),
 * and a FIFO or device ("-" is stdout) is written directly. cli_out_open returns an exit
 * code (after printing why) on error.
 */
typedef struct cli_out {
  FILE *f;
  char *path; /* final path (a link's target), NULL when writing directly */
  char *tmp;
  int direct; /* a FIFO or device: written in place, never renamed over */
} cli_out_t;
int cli_out_open(const char *cmd, const char *path, cli_out_t *o);
/* Close and rename (ok != 0) or close and delete (ok == 0). Returns CLI_OK or an error. */
int cli_out_close(const char *cmd, cli_out_t *o, int ok);

/* Subcommands: argv[0] is the subcommand's name. */
int cmd_tree(int argc, char **argv);
int cmd_knn(int argc, char **argv);
int cmd_range(int argc, char **argv);
int cmd_radius(int argc, char **argv);
int cmd_locate(int argc, char **argv);
int cmd_collide(int argc, char **argv);
int cmd_raycast(int argc, char **argv);
int cmd_geo(int argc, char **argv);
int cmd_mesh(int argc, char **argv);
int cmd_world(int argc, char **argv);
int cmd_simulate(int argc, char **argv);

#endif /* QUADKIT_CLI_H */
