/* The C locale for numbers as text (index/textloc.h). */
#define _GNU_SOURCE /* newlocale, uselocale, locale_t (POSIX 2008); glibc's strtod_l */

#include <locale.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>

#include "index/textloc.h"

/* The scope keeps a locale_t as a pointer (textloc.h does not need <locale.h>'s POSIX part). */
_Static_assert(sizeof(locale_t) == sizeof(void *), "locale_t is a pointer");

/* Made once, never freed: the first thread to store it wins, a racing one frees its own. */
static _Atomic(void *) c_locale;

static locale_t get_c_locale(void) {
  void *l = atomic_load_explicit(&c_locale, memory_order_acquire);
  if (l) return (locale_t)l;
  locale_t made = newlocale(LC_ALL_MASK, "C", (locale_t)0);
  if (made == (locale_t)0) return (locale_t)0;
  void *expected = NULL;
  if (atomic_compare_exchange_strong_explicit(&c_locale, &expected, (void *)made,
                                              memory_order_acq_rel, memory_order_acquire))
    return made;
  freelocale(made);
  return (locale_t)expected;
}

qk_status_t qk__c_locale_ready(void) { return get_c_locale() ? QK_OK : QK_ERR_NOMEM; }

double qk__strtod(const char *s, char **end) {
  locale_t c = get_c_locale();
  if (!c) return strtod(s, end);
#if defined(__GLIBC__) /* as fast as strtod; two uselocale calls add 10-15 ns to its 80 */
  return strtod_l(s, end, c);
#else
  locale_t old = uselocale(c);
  double d = strtod(s, end); /* (errno as strtod leaves it: uselocale succeeds silently) */
  uselocale(old);
  return d;
#endif
}

int qk__vsnprintf(char *buf, size_t size, const char *fmt, va_list ap) {
  locale_t c = get_c_locale();
  if (!c) return vsnprintf(buf, size, fmt, ap);
  locale_t old = uselocale(c);
  int n = vsnprintf(buf, size, fmt, ap);
  uselocale(old);
  return n;
}

qk_status_t qk__c_locale_enter(qk__c_scope_t *s) {
  locale_t c = get_c_locale();
  s->saved = NULL;
  if (!c) return QK_ERR_NOMEM;
  s->saved = (void *)uselocale(c);
  return QK_OK;
}

void qk__c_locale_leave(const qk__c_scope_t *s) {
  if (s->saved) uselocale((locale_t)s->saved);
}
