/**
 * \file io.h
 * \brief Reading points (and other numeric columns) from CSV text, with the rules of the
 *        `quadkit` command-line tool and errors that say where.
 *
 * The rules: one record per line (LF or CRLF; a UTF-8 byte order mark on the first line
 * is skipped); fields separated by commas, a field may be quoted with double quotes
 * (`""` inside for a quote; a CR alone inside a line is an error); a quoted field may hold
 * line breaks (RFC 4180), and its record then spans several lines of the file: every
 * line number (errors, the row callback) is the file's physical line, 1-based, where the
 * record starts, or for an error in a field, where that field starts (its column counted
 * from that line's start); lines holding only blanks are skipped. A quote left open to
 * the end of the input is an error, in a field not read too. The first non-blank line is
 * a header when options say so, or (by default) when none of its selected fields is a
 * number (a first line "x1,2" is data, and an error); columns may then be selected by name.
 * Every other line is a data row: its selected fields must be decimal numbers (an optional
 * sign, digits with an optional decimal point, an optional exponent: `-1.5e3`, `.5`, `5.`;
 * blanks around allowed; strtod's hexadecimal `0x10` is refused) and finite; the other
 * fields may hold anything. A row's 0-based index among the data rows is its id. Data
 * rows are limited to 2^32 - 2 (the ids a tree holds). A NUL byte is binary data, refused
 * at its line and column: reading stops there, so a binary stream without line breaks
 * (/dev/zero) is not taken into memory first. The library never prints: a rejected input
 * fills a qk_error_t. Numbers are read in the C locale whatever locale the program or the
 * calling thread set (setlocale, uselocale): "1.5" is 1.5 and "1,5" is no number under a
 * German locale too.
 */
#ifndef QUADKIT_IO_H
#define QUADKIT_IO_H

#include <stdio.h>

#include "quadkit/common.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Whether the first non-blank line is a header. */
typedef enum qk_csv_header {
  QK_CSV_HEADER_AUTO = 0, /**< a header when none of its selected fields is a number, or
                               when columns are selected by name */
  QK_CSV_HEADER_YES = 1,  /**< always a header */
  QK_CSV_HEADER_NO = 2    /**< never: every non-blank line is data */
} qk_csv_header_t;

/**
 * Called for the header line (row == SIZE_MAX) and for each data row once it has been
 * read without error, with the 1-based physical line where it starts and the record's whole text,
 * every field included (NUL-terminated, len bytes, byte order mark and line ending removed; a
 * line break inside a quoted field kept as one LF), valid only during the call.
 * Returning anything but QK_OK stops the reader, which returns that status.
 */
typedef qk_status_t (*qk_csv_row_fn)(void *ud, size_t row, unsigned long lineno, const char *line,
                                     size_t len);

/** How to read a CSV input. Initialise with qk_csv_options_init(). */
typedef struct qk_csv_options {
  /** The columns to read, in order, comma-separated: header names or 1-based numbers,
   *  e.g. "lon,lat" or "3,2" (a name made of digits only is taken as a number); two that
   *  select one field ("x,1" when x is the first) are an error. NULL: the first columns
   *  (1,2 for points). */
  const char *columns;
  qk_csv_header_t header; /**< default QK_CSV_HEADER_AUTO */
  qk_csv_row_fn on_row;   /**< optional; see qk_csv_row_fn */
  void *ud;               /**< passed to on_row unchanged */
} qk_csv_options_t;

/**
 * Set the defaults: first columns, header detected, no callback.
 * \param [out] opt the options to initialise.
 */
void qk_csv_options_init(qk_csv_options_t *opt);

/**
 * Read points (two columns: x then y) from a CSV file.
 * \param [in] path the file to read.
 * \param [in] opt options (columns "X,Y", header rule, callback), or NULL for the
 *             defaults.
 * \param [in] alloc the allocator for the result and scratch memory, or NULL for libc.
 * \param [out] pts the points in data-row order, allocated with alloc (the caller frees
 *              them with the same allocator, size *n * sizeof(qk_point_t); free() when
 *              alloc is NULL); NULL when there are none or on error.
 * \param [out] n how many points (0 for a file without data rows, which is not an error).
 * \param [out] err where and why the input was rejected: line, 1-based byte column of
 *              the offending field, its data row in item (SIZE_MAX when not a data row),
 *              and a message naming the field and value but not the file or line (print
 *              "FILE:LINE:COLUMN: message"); may be NULL.
 * \return QK_OK; QK_ERR_IO when the file cannot be opened or read; QK_ERR_PARSE for a
 *         malformed line (a field that is not a number, a missing field, a NUL byte, an
 *         unterminated quote, a column name the header lacks); QK_ERR_NONFINITE for a
 *         NaN or infinite value; QK_ERR_INVALID for malformed options; QK_ERR_LIMIT past
 *         2^32 - 2 rows or for a nonzero value below the smallest double ("1e-400", which
 *         would read as 0); QK_ERR_NOMEM; or the callback's status. On error nothing is
 *         allocated.
 */
qk_status_t qk_points_read_csv(const char *path, const qk_csv_options_t *opt,
                               const qk_allocator_t *alloc, qk_point_t **pts, size_t *n,
                               qk_error_t *err);

/**
 * As qk_points_read_csv(), from an open stream (read to its end, not closed).
 * \param [in] f the stream.
 * \param [in] opt as for qk_points_read_csv().
 * \param [in] alloc as for qk_points_read_csv().
 * \param [out] pts as for qk_points_read_csv().
 * \param [out] n as for qk_points_read_csv().
 * \param [out] err as for qk_points_read_csv().
 * \return as for qk_points_read_csv().
 */
qk_status_t qk_points_read_csv_file(FILE *f, const qk_csv_options_t *opt,
                                    const qk_allocator_t *alloc, qk_point_t **pts, size_t *n,
                                    qk_error_t *err);

/**
 * Read `ncols` numeric columns per data row, the first `nrequired` of them required (a
 * missing or empty optional field reads as NaN; a present one must be a finite number).
 * \param [in] f the stream, read to its end (not closed).
 * \param [in] opt as for qk_points_read_csv() (opt->columns lists ncols columns; NULL:
 *             the first ncols).
 * \param [in] ncols columns per row, 1 to 64.
 * \param [in] nrequired how many of them are required, 1 to ncols.
 * \param [in] alloc as for qk_points_read_csv().
 * \param [out] values rows * ncols doubles, row-major, allocated with alloc; NULL when
 *              there are no rows or on error.
 * \param [out] rows how many data rows.
 * \param [out] err as for qk_points_read_csv().
 * \return as for qk_points_read_csv().
 */
qk_status_t qk_csv_read_values(FILE *f, const qk_csv_options_t *opt, size_t ncols, size_t nrequired,
                               const qk_allocator_t *alloc, double **values, size_t *rows,
                               qk_error_t *err);

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_IO_H */
