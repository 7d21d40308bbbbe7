/*
 * QK__ALWAYS_INLINE: `inline`, and with GCC or Clang made to inline wherever it is called.
 * The library's specialised inner loops (a function written once and expanded with a
 * constant argument per case) rely on it for their speed.
 *
 * Not under ASan or TSan (CI's sanitizer builds and the fuzz targets all use one): there the
 * forced expansion made single functions of over 100 KB of instrumented code whose
 * register allocation took most of the build (collide/world_search.c 17.5 s of one
 * processor under ASan + UBSan, 3.4 s without), and the sanitizer builds are for finding
 * memory errors and races, not for speed. The compiler decides there; what the code does
 * is the same.
 */
#ifndef QK_INDEX_INLINE_H
#define QK_INDEX_INLINE_H

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define QK__SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define QK__SANITIZED 1
#endif
#endif

#if defined(__GNUC__) && !defined(QK__SANITIZED)
#define QK__ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define QK__ALWAYS_INLINE inline
#endif

#endif
