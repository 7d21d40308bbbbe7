/*
 * Numbers as text in the C locale, whatever locale the program set (setlocale) or the
 * calling thread uses (uselocale): under a German or French locale "1.5" still reads as
 * 1.5 and 1.5 is still written "1.5", not "1,5". Every module that reads or writes
 * numbers as text goes through these (index/textloc.c): the readers' strtod, the
 * writers' whole call, the error messages' formatting. Not API.
 *
 * One C locale (POSIX 2008 newlocale) is made on first use and kept for the process; its
 * memory is libc's, not the allocator hook's (glibc and musl allocate none for "C"). When
 * it cannot be made (out of memory), readers and writers return QK_ERR_NOMEM before any
 * work, and a message is formatted in the caller's locale rather than not at all.
 */
#ifndef QUADKIT_INDEX_TEXTLOC_H
#define QUADKIT_INDEX_TEXTLOC_H

#include <stdarg.h>
#include <stddef.h>

#include "quadkit/common.h"

/* Whether the C locale is there (made now if it was not): QK_OK, or QK_ERR_NOMEM when
 * newlocale failed. A reader calls it once at its entry; qk__strtod() then never falls
 * back. */
qk_status_t qk__c_locale_ready(void);

/* strtod in the C locale (in the thread's own when the C locale could not be made). */
double qk__strtod(const char *s, char **end);

/* vsnprintf in the C locale (in the thread's own when the C locale could not be made). */
int qk__vsnprintf(char *buf, size_t size, const char *fmt, va_list ap);

/* The calling thread in the C locale for a writer's whole call: qk__c_locale_enter()
 * switches (QK_ERR_NOMEM, nothing switched, when the C locale could not be made), and
 * qk__c_locale_leave() restores the thread's locale on every path out. */
typedef struct qk__c_scope {
  void *saved; /* the thread's locale_t (or LC_GLOBAL_LOCALE) */
} qk__c_scope_t;
qk_status_t qk__c_locale_enter(qk__c_scope_t *s);
void qk__c_locale_leave(const qk__c_scope_t *s);

/* The body of a public writer: return `call` (a qk_status_t) made in the C locale, or
 * QK_ERR_NOMEM when the C locale could not be made. */
#define QK__RETURN_IN_C_LOCALE(call)                                                               \
  do {                                                                                             \
    qk__c_scope_t scope_;                                                                          \
    qk_status_t st_ = qk__c_locale_enter(&scope_);                                                 \
    if (st_ == QK_OK) {                                                                            \
      st_ = (call);                                                                                \
      qk__c_locale_leave(&scope_);                                                                 \
    }                                                                                              \
    return st_;                                                                                    \
  } while (0)

#endif /* QUADKIT_INDEX_TEXTLOC_H */
