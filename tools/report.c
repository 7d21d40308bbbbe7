/* Messages of the command-line tool, and library statuses mapped to exit codes. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"

/* The length of the UTF-8 sequence at s (n bytes left) that is printable text: 0 when it
 * is malformed, overlong, a surrogate, beyond U+10FFFF or a C1 control (U+0080..U+009F). */
static size_t utf8_printable(const unsigned char *s, size_t n) {
  size_t len = s[0] >= 0xF0 ? 4 : s[0] >= 0xE0 ? 3 : 2;
  if (s[0] < 0xC2 || s[0] > 0xF4 || len > n) return 0;
  unsigned long c = s[0] & (0x3F >> (len - 1));
  for (size_t i = 1; i < len; i++) {
    if ((s[i] & 0xC0) != 0x80) return 0;
    c = c << 6 | (s[i] & 0x3F);
  }
  static const unsigned long least[] = {0, 0, 0x80, 0x800, 0x10000};
  if (c < least[len] || c > 0x10FFFF || (c >= 0xD800 && c <= 0xDFFF) || c < 0xA0) return 0;
  return len;
}

void cli_vmsg(const char *fmt, va_list ap) {
  char small[1024], *buf = small;
  va_list ap2;
  va_copy(ap2, ap);
  int n = vsnprintf(small, sizeof small, fmt, ap);
  if (n >= (int)sizeof small && (buf = malloc((size_t)n + 1)))
    vsnprintf(buf, (size_t)n + 1, fmt, ap2);
  va_end(ap2);
  if (!buf) buf = small; /* (cut short rather than lost) */
  size_t len = n < 0 ? 0 : strlen(buf);
  const unsigned char *s = (const unsigned char *)buf;
  for (size_t i = 0; i < len;) {
    size_t k = 0;
    if (s[i] >= 0x80) k = utf8_printable(s + i, len - i);
    if (k) {
      fwrite(s + i, 1, k, stderr);
      i += k;
    } else if (s[i] < 0x20 && s[i] != '\n' && s[i] != '\t') {
      fprintf(stderr, "\\x%02X", s[i++]);
    } else if (s[i] == 0x7F || s[i] >= 0x80) {
      fprintf(stderr, "\\x%02X", s[i++]);
    } else {
      fputc(s[i++], stderr);
    }
  }
  if (buf != small) free(buf);
}

const char *cli_cut(const char *val, size_t max, char *buf) {
  size_t n = strlen(val);
  if (n <= max) return val;
  n = max;
  while (n > 0 && ((unsigned char)val[n] & 0xC0) == 0x80) n--; /* (val[n]: the first byte cut) */
  memcpy(buf, val, n);
  memcpy(buf + n, "...", 4);
  return buf;
}

void cli_msg(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  cli_vmsg(fmt, ap);
  va_end(ap);
}

void cli_error(const char *cmd, const char *fmt, ...) {
  va_list ap;
  fprintf(stderr, "quadkit %s: ", cmd);
  va_start(ap, fmt);
  cli_vmsg(fmt, ap);
  va_end(ap);
  fputc('\n', stderr);
}

int cli_status(const char *cmd, const char *what, qk_status_t st) {
  if (st == QK_OK) return CLI_OK;
  cli_error(cmd, "%s: %s", what, qk_strerror(st));
  switch (st) {
  case QK_ERR_NOMEM:
  case QK_ERR_CORRUPT:
  case QK_ERR_IO:
  case QK_ERR_UNSUPPORTED:
    return CLI_INTERNAL;
  default:
    return CLI_BAD_INPUT;
  }
}

int cli_build_tree(const char *cmd, const char *path, const qk_point_t *pts, size_t n,
                   const qk_tree_options_t *opt, qk_tree_t **out) {
  qk_status_t st = qk_tree_build(pts, n, opt, out);
  if (st == QK_ERR_LIMIT && n > 0) {
    /* The likely cause: an extent no double can hold. Name the values. */
    double x0 = pts[0].x, x1 = pts[0].x, y0 = pts[0].y, y1 = pts[0].y;
    for (size_t i = 1; i < n; i++) {
      x0 = pts[i].x < x0 ? pts[i].x : x0;
      x1 = pts[i].x > x1 ? pts[i].x : x1;
      y0 = pts[i].y < y0 ? pts[i].y : y0;
      y1 = pts[i].y > y1 ? pts[i].y : y1;
    }
    if (!isfinite(x1 - x0) || !isfinite(y1 - y0)) {
      cli_error(cmd,
                "%s: the points span x from %.17g to %.17g and y from %.17g to %.17g, "
                "an extent too large for a double",
                path, x0, x1, y0, y1);
      return CLI_BAD_INPUT;
    }
  }
  return cli_status(cmd, path, st);
}
