/* Option values of the command-line tool: whole numbers, finite numbers, column pairs. */
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"

int cli_parse_u32(const char *cmd, const char *opt, const char *s, unsigned long min,
                  unsigned long max, unsigned long *out) {
  char *end;
  if (!s) {
    cli_error(cmd, "%s needs a value", opt);
    return 1;
  }
  errno = 0;
  unsigned long v = strtoul(s, &end, 10);
  if (errno || end == s || *end || s[0] == '-' || v < min || v > max) {
    cli_error(cmd, "%s must be a whole number from %lu to %lu, not '%s'", opt, min, max, s);
    return 1;
  }
  *out = v;
  return 0;
}

int cli_parse_double(const char *cmd, const char *opt, const char *s, double *out) {
  char *end;
  if (!s) {
    cli_error(cmd, "%s needs a value", opt);
    return 1;
  }
  errno = 0;
  double v = strtod(s, &end);
  if (end == s || *end || !isfinite(v)) {
    cli_error(cmd, "%s must be a finite number, not '%s'", opt, s);
    return 1;
  }
  *out = v;
  return 0;
}

int cli_parse_xy(const char *cmd, const char *opt, const char *s, const char **out) {
  if (!s) {
    cli_error(cmd, "%s needs a value", opt);
    return 1;
  }
  const char *comma = strchr(s, ',');
  if (!comma || comma == s || !comma[1] || strchr(comma + 1, ',')) {
    cli_error(cmd, "%s must be two columns X,Y (header names or 1-based numbers), not '%s'", opt,
              s);
    return 1;
  }
  /* A number names a column from 1 (as in join's --xy): 0 is a usage error here, not a
   * reading error later. */
  const char *part[2] = {s, comma + 1};
  size_t len[2] = {(size_t)(comma - s), strlen(comma + 1)};
  for (int i = 0; i < 2; i++)
    if (strspn(part[i], "0123456789") == len[i] && strspn(part[i], "0") == len[i]) {
      cli_error(cmd, "%s: column numbers start at 1, not '%.*s'", opt, (int)len[i], part[i]);
      return 1;
    }
  *out = s;
  return 0;
}
