/* Option values of the command-line tool: whole numbers, finite numbers, column pairs. */
#include <ctype.h>
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
  /* digits only: strtoul also takes leading blanks and a sign (' 3' was 3, '3 ' an error) */
  if (errno || !isdigit((unsigned char)s[0]) || *end || v < min || v > max) {
    cli_error(cmd, "%s must be a whole number from %lu to %lu, not '%s'", opt, min, max, s);
    return 1;
  }
  *out = v;
  return 0;
}

/* Whether a number's text has a nonzero digit before its exponent (it is not zero). */
static int nonzero_digits(const char *s) {
  for (; *s && *s != 'e' && *s != 'E'; s++)
    if (*s >= '1' && *s <= '9') return 1;
  return 0;
}

int cli_number(const char *s, double *v) {
  size_t i = 0, d = 0;
  if (s[i] == '+' || s[i] == '-') i++;
  static const char *const words[] = {"infinity", "inf", "nan"};
  int word = 0;
  for (int w = 0; w < 3 && !word; w++) { /* (strtod's words: numbers, not finite) */
    size_t k = strlen(words[w]), j = 0;
    while (j < k && s[i + j] && (s[i + j] | 0x20) == words[w][j]) j++;
    word = j == k && !s[i + k];
  }
  if (!word) {
    while (s[i] >= '0' && s[i] <= '9') i++, d++;
    if (s[i] == '.')
      for (i++; s[i] >= '0' && s[i] <= '9'; i++) d++;
    if (d && (s[i] == 'e' || s[i] == 'E')) {
      size_t x = 0;
      i += s[i + 1] == '+' || s[i + 1] == '-' ? 2 : 1;
      while (s[i] >= '0' && s[i] <= '9') i++, x++;
      if (!x) d = 0;
    }
    if (!d || s[i]) {
      size_t h = s[0] == '+' || s[0] == '-';
      return s[h] == '0' && (s[h + 1] | 0x20) == 'x' ? -1 : 0;
    }
  }
  *v = strtod(s, NULL);
  return *v == 0 && nonzero_digits(s) ? -2 : 1;
}

int cli_parse_double(const char *cmd, const char *opt, const char *s, double *out) {
  if (!s) {
    cli_error(cmd, "%s needs a value", opt);
    return 1;
  }
  double v;
  int got = cli_number(s, &v);
  if (got == -2) {
    cli_error(cmd, "%s: '%s' is below the smallest double (it would read as 0)", opt, s);
    return 1;
  }
  if (got != 1 || !isfinite(v)) {
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
  /* Past 100000 (the readers' last column), a number is refused here, by its digits: two
   * numbers beyond an unsigned long both read as ULONG_MAX, and were "the same column". */
  for (int i = 0; i < 2; i++) {
    size_t z = strspn(part[i], "0");
    if (strspn(part[i], "0123456789") == len[i] &&
        (len[i] - z > 6 || strtoul(part[i], NULL, 10) > 100000)) {
      cli_error(cmd, "%s: column number %.*s must be from 1 to 100000", opt, (int)len[i], part[i]);
      return 1;
    }
  }
  /* x and y from one column (--xy 2,2 or lat,lat: a slip) would read every point onto
   * the diagonal, without a word. Numbers are compared by value (2 and 02). */
  int digits = strspn(part[0], "0123456789") == len[0] && strspn(part[1], "0123456789") == len[1];
  if (digits ? strtoul(part[0], NULL, 10) == strtoul(part[1], NULL, 10)
             : len[0] == len[1] && !memcmp(part[0], part[1], len[0])) {
    cli_error(cmd, "%s %s: x and y name the same column", opt, s);
    return 1;
  }
  *out = s;
  return 0;
}
