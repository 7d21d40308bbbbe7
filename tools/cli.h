/*
 * Shared plumbing of the `quadkit` command-line tool: exit codes, CSV input (csv.c),
 * messages (report.c), option parsing helpers (args.c), the atomic output writer (out.c)
 * and the subcommand entry points.
 */
#ifndef QUADKIT_CLI_H
#define QUADKIT_CLI_H

#include <stddef.h>
#include <stdarg.h>
#include <stdio.h>

#include "quadkit/quadkit.h"

/* Exit codes (documented in the README and in --help). */
enum { CLI_OK = 0, CLI_BAD_INPUT = 1, CLI_USAGE = 2, CLI_INTERNAL = 3 };

/*
 * CSV input (tools/csv.c), through the library's reader (include/quadkit/io.h): errors are
 * printed as "quadkit: FILE:LINE:COLUMN: reason" and give CLI_BAD_INPUT (CLI_INTERNAL when
 * out of memory). A data row's 0-based index is its id.
 */

/* The text of every data row of an input, its line number, and its header, for --keep
 * and for messages about a row. width: the most fields any of them has. */
typedef struct cli_rows {
  char **text;           /* per row; NULL when the rows' text is not kept */
  unsigned long *lineno; /* per row */
  size_t n, cap;
  char *header; /* NULL when the input has none */
  size_t width;
  int keep_text;
} cli_rows_t;
void cli_rows_free(cli_rows_t *r);

/* A numeric table: rows x cols doubles, row-major; a missing optional field is NAN. */
typedef struct cli_table {
  double *v;
  size_t rows;
  int cols;
} cli_table_t;

/* Read `cols` columns (the first `required` of them required) from the first columns of
 * path. rows (may be NULL) receives the line numbers and, when rows->keep_text, the text. */
int cli_read_table(const char *path, int required, int cols, cli_rows_t *rows, cli_table_t *out);
void cli_table_free(cli_table_t *t);

/* Read points: columns `xy` ("X,Y" names or numbers; NULL: the first two) into a malloc'd
 * array; at least one data row. rows as for cli_read_table. */
int cli_read_points(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                    size_t *n);
/* What a carriage return left inside a line once its end is cut means to the user. */
#define CLI_LONE_CR "a carriage return inside the line (line ends must be LF or CRLF, not CR alone)"
/* Cut a line's end (LF, CRLF) in place, *len its length before and after; nonzero when a
 * carriage return is left inside it: CR-only line ends, where the rest of the file would
 * read as this one line. */
int cli_cut_line_end(char *line, size_t *len);

/* The longest physical line a CSV input (points, queries, boxes, discs, rays, objects,
 * moves) may have: 1 MiB, thousands of times a real row. Past it the input is refused
 * with its line and the limit, before more is read: a binary file or an endless line
 * without a line break (/dev/zero, a wrong file) would otherwise be taken into memory
 * until it ran out. Documented in the README's CLI section and `quadkit --help`. */
#define CLI_MAX_LINE (1024UL * 1024UL)

/* The most bytes the line reader keeps of an input that is not a regular file (a pipe, a
 * FIFO, a device: cli_screen_input keeps such an input in memory as read, since it cannot
 * be read twice): 2^31 - 1, the limit the GeoJSON readers put on a stream
 * (region/geojson.c), and the mesher's GeoJSON input's (tools/mesh_geojson.c). An endless
 * stream of short lines (`yes 1,2 | quadkit tree /dev/stdin`) would otherwise be kept until
 * memory ran out; past the limit it is refused, exit 1. A regular
 * file has none. */
#define CLI_STREAM_MAX 2147483647UL

/* The tool's one line reader for CSV text: read in 64 KiB chunks (fread), each physical
 * line checked as it comes in, so that a NUL byte (binary data) or a line longer than
 * CLI_MAX_LINE stops it at once. Initialise with cli_lines_init, free with
 * cli_lines_free. With `tee` set, every byte read is also kept in tee_buf (tee_len bytes,
 * malloc'd; the caller frees it): the input as read, for a second reader when it cannot
 * be read again (a pipe, a FIFO, a device). */
typedef struct cli_lines {
  FILE *f;
  char *chunk;
  size_t cpos, clen;
  int eof;
  char *line; /* the current line (cli_read_line) or record (cli_read_record) */
  size_t cap;
  char *part; /* a record's later lines, before they are joined to `line` */
  size_t pcap;
  unsigned long phys;  /* physical lines read (the current one included) */
  unsigned long first; /* the physical line where the current record starts */
  unsigned long col;   /* on -2: the 1-based byte column (of a NUL, or of a lone CR
                          from cli_read_record), or 0 */
  int tee;
  char *tee_buf;
  size_t tee_len, tee_cap;
} cli_lines_t;
void cli_lines_init(cli_lines_t *r, FILE *f);
void cli_lines_free(cli_lines_t *r);

/* One physical line into r->line (NUL-terminated, its LF cut but not a CR before it:
 * cli_cut_line_end does that). Returns its length; -1 at the end of the input or on a
 * read error (ferror(r->f) tells); -2 for a NUL byte or a line past CLI_MAX_LINE (*why
 * says which, r->phys its line, r->col the NUL's column); -3 out of memory; -4, with tee
 * set, when the input passes CLI_STREAM_MAX bytes (*why says so). */
long cli_read_line(cli_lines_t *r, const char **why);

/* One CSV record into r->line: one physical line, or several joined by LF while a
 * quoted field is open (RFC 4180), as the library's reader does (include/quadkit/io.h);
 * each line's ending cut. r->phys counts the physical lines read, r->first is the one
 * where the record starts. Returns the record's length; -1 at the end of the input or on
 * a read error (ferror tells); -2 for a NUL byte, a line too long or a lone CR (*why says
 * which, on physical line r->phys); -3 out of memory. A record that the input ends inside
 * a quoted field is returned with *why set (NULL otherwise): the caller names the field. */
long cli_read_record(cli_lines_t *r, const char **why);

/* The exit code for how a line reader stopped: `got` is cli_read_line's or
 * cli_read_record's last return, `why` its reason. -2 is refused as bad input and -3 as
 * out of memory, and the end of the input is CLI_OK unless the stream had a read error;
 * each failure prints "quadkit CMD: PATH:LINE[:COL]: ..." (the column when `columns` and
 * known; cmd NULL: "quadkit: ..."). */
int cli_lines_status(const char *cmd, const char *path, const cli_lines_t *r, long got,
                     const char *why, int columns);

/* Screen an open input with the tool's line reader before a library reader (which takes
 * a line of any length into memory) reads it: a NUL byte or a line past CLI_MAX_LINE is
 * refused ("quadkit CMD: PATH:LINE[:COL]: why", the column when `columns`, as the
 * command's other messages; cmd NULL: "quadkit: ..."). A regular file
 * is then set back to where the screen began reading (not to byte 0: standard input may be
 * a file already partly read); any other input is kept in memory as read and *f becomes a stream
 * over it (*f closed unless it is stdin; *copy, the bytes, freed by the caller after
 * fclose(*f); NULL when nothing was kept). Returns an exit code. */
int cli_screen_input(const char *cmd, const char *path, int columns, FILE **f, char **copy);

/* The same for a file of queries, which may have no data rows (*n = 0, *pts NULL): a
 * query command answers an empty batch with its header line alone. */
int cli_read_queries(const char *path, const char *xy, cli_rows_t *rows, qk_point_t **pts,
                     size_t *n);

/* Write `text` (one row's or the header's fields) then empty fields up to `width`, each
 * preceded by a comma; with prefix, the header's names prefixed (names 1..width when
 * text is NULL). */
void cli_write_fields(FILE *f, const char *text, size_t width, const char *prefix);

/* val for a message: itself when at most max bytes long, else its first max bytes (a
 * UTF-8 character not cut in two) and "...", in buf (max + 4 bytes). */
const char *cli_cut(const char *val, size_t max, char *buf);
/* Print a message to stderr (printf-style), every byte of it that a terminal would act on
 * written as \xNN: control characters but newline and tab, DEL, C1 controls and bytes
 * that are not UTF-8 (messages quote input text, which may hold escape sequences that
 * would clear the screen or set the window title; valid UTF-8, a name such as "Côte
 * d'Ivoire", is kept). */
void cli_msg(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;
/* The same, from a va_list. */
void cli_vmsg(const char *fmt, va_list ap);

/* Print "quadkit CMD: message" to stderr (printf-style), as cli_msg. */
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

/* Option values (tools/args.c); print a usage error and return nonzero when malformed. */
int cli_parse_u32(const char *cmd, const char *opt, const char *s, unsigned long min,
                  unsigned long max, unsigned long *out);
int cli_parse_double(const char *cmd, const char *opt, const char *s, double *out);
/* A whole string as a decimal number (optional sign, digits with an optional point, an
 * optional exponent; or strtod's inf, infinity, nan in any case, which set a non-finite
 * *v): 1 and *v set; 0 when it is not one; -1 when it is hexadecimal (0x...), which
 * strtod would take but the tool's inputs do not; -2 when it is a nonzero number below the
 * smallest double, which strtod reads as 0 (*v set to that 0). No blanks around. */
int cli_number(const char *s, double *v);
/* --xy X,Y: two column names or 1-based numbers, comma-separated. */
int cli_parse_xy(const char *cmd, const char *opt, const char *s, const char **out);

/*
 * The atomic output writer (tools/out.c). Output files are written to "PATH.tmp.PID" and renamed on
 * success so that a failed run leaves no half-written file; a symbolic link is written through (its
 * target replaced, or created when the link dangles), and a FIFO or device ("-" is stdout) is
 * written directly. cli_out_open returns an exit code (after printing why) on error: a usage error
 * for an output that is one of the inputs (a regular file, a FIFO or pipe, by device and inode,
 * however it is named: /dev/stdin, /proc/self/fd/N, a link, "-" for standard output) or that
 * another open output of the command writes (standard output included: a command that prints to
 * it opens "-" too, so that `--svg /dev/stdout` is refused beside it).
 */
typedef struct cli_out {
  FILE *f;
  char *path; /* final path (a link's target); the path given when writing directly */
  char *tmp;
  int direct;  /* a FIFO or device: written in place, never renamed over */
  char *key;   /* canonical name while open (two outputs naming one file are refused) */
  unsigned id; /* the entry of this output among those open (out.c) */
} cli_out_t;
int cli_out_open(const char *cmd, const char *path, cli_out_t *o);
/* Close and rename (ok != 0) or close and delete (ok == 0). Returns CLI_OK or an error. */
int cli_out_close(const char *cmd, cli_out_t *o, int ok);

/* Open an input file for reading ("rb"). NULL after printing "quadkit CMD: PATH: cannot
 * open: why" (cmd NULL: "quadkit: PATH: ...")
 * (cannot open: the system's reason; a directory: "is a directory", which fopen lets
 * through and the first read then fails on with a vague "read error"). */
FILE *cli_open_input(const char *cmd, const char *path);
/* Record an input that is read by other means than cli_open_input (the library's readers;
 * "-": standard input), before any output is opened: cli_out_open refuses to write over an
 * input or into the pipe it is read from (exit 2). */
void cli_note_input(const char *path);

/* Standard input as an input: "-" names it wherever a CSV file is read, as `mesh -` does.
 * cli_input_open opens PATH as cli_open_input does, or, for "-", notes standard input as
 * an input (cli_note_input) and returns stdin, from where it stood when "-" was first
 * opened (a regular file named "-" twice is read twice from there). NULL after printing
 * why. cli_input_close closes what it opened (never stdin). cli_input_name: the name
 * messages give an input ("<stdin>" for "-"). */
FILE *cli_input_open(const char *cmd, const char *path);
void cli_input_close(FILE *f);
const char *cli_input_name(const char *path);
/* The inputs of a command (paths[0..n), n <= 8, NULL entries skipped; "-" is standard
 * input) that reach one file which can be read only once (a pipe or FIFO, a socket, a
 * terminal: `cat p.csv | quadkit knn /dev/stdin /dev/stdin` read the pipe whole for the
 * points and found it empty for the queries): a usage error naming both, exit 2, before
 * anything is read. A regular file, or a device read anew at each open, may be named
 * twice. */
int cli_inputs_once(const char *cmd, const char *const *paths, int n);

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
int cmd_join(int argc, char **argv);    /* tools/cmd_region.c */
int cmd_regions(int argc, char **argv); /* tools/cmd_region.c */
int cmd_world(int argc, char **argv);
int cmd_simulate(int argc, char **argv);

#endif /* QUADKIT_CLI_H */
