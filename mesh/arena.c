/*
 * The mesher's block arena (issue 12, seventeenth session): where the caller gives no
 * allocator, all three modes take their large blocks (64 KB and more: the tree's nodes,
 * the corner map, the general mode's triangulation and queues, the triangle and vertex
 * arrays) from 2 MB-aligned chunks marked for transparent huge pages, instead of from
 * malloc.
 *
 * Why: malloc hands a freed large block back to the kernel (munmap, or a trim of the heap
 * top), so every call touched its 5-8 MB of blocks as fresh 4 KB pages, one page fault
 * each. On the seventeenth session's virtual machine a fault costs 6-30 us (about 0.2 us
 * on a usual machine), and the dyadic bench input's 1,433 faults a call took 5-10x the
 * mesher's own work. A chunk with MADV_HUGEPAGE faults once per 2 MB.
 *
 * The arena is a qk_alloc_fn. Blocks are placed by bumping a chunk's top; a freed block at
 * a top is taken back, a chunk whose blocks are all freed is unmapped (or kept empty when
 * it is the last one, of one huge page), and a block at a top grows in place. A block of
 * 2 MB or more has its chunk to itself, so that freeing it gives the chunk back. Smaller blocks,
 * and blocks reallocated below 64 KB from libc, stay with libc; where a block lives is known from
 * its address. Once the mesh is made the arena is sealed: from then on it only passes new
 * blocks to libc and counts frees of its own blocks, so threads that read (write out) one
 * mesh at once never change it; its chunks go when the mesh is freed.
 *
 * Chunks kept between meshes (thirty-first session). A chunk given back goes to a
 * process-wide cache of at most KEEP_BYTES instead of to the kernel, and the next
 * arena's chunks come from there first (the smallest kept mapping that holds the size,
 * whose rest stays kept). Why: on this guest, memory mapped anew after other code has
 * used and freed much memory costs more to touch than memory reused at once, though the
 * process counts almost no page faults: with 200 MB malloc'd, written and freed before
 * each call, Iceland at extent/256 took 24.7-25.7 ms a call against 19.6-20.5 without,
 * and 20.7-21.2 with chunks kept; the bench's random polygon, each call timed after CGAL's
 * and gmsh's, went from 8.6x to 15.7-16.2x CGAL (docs/mesh.md, "Chunks kept between
 * meshes"). A kept chunk is handed out as it was left (nothing in the mesher reads a block
 * before writing it; test_mesh_arena fills the kept chunks with garbage and meshes again).
 * qk_mesh_trim() gives the cache back. The cache's lock is only ever tried: a thread
 * that finds it taken maps or unmaps by itself, so no thread waits and a child forked
 * while another thread held it still works.
 */
#define _DEFAULT_SOURCE
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh_internal.h"

#if defined(__linux__)
#include <sys/mman.h>
#endif

/* Off under AddressSanitizer, which does not see inside the chunks: the mesher's large
 * arrays stay where it checks them. */
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define ARENA_ASAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__)
#define ARENA_ASAN 1
#endif

#if defined(__linux__) && defined(MADV_HUGEPAGE) && defined(MAP_ANONYMOUS) && !defined(ARENA_ASAN)
#define ARENA_ON 1
#else
#define ARENA_ON 0
#endif

#define ARENA_MIN ((size_t)64 << 10) /* smaller blocks stay with libc */
#define CHUNK ((size_t)2 << 20)      /* a transparent huge page */
#define ALIGN ((size_t)64)

typedef struct chunk {
  char *base;
  size_t size, top; /* bytes mapped, bytes handed out from base */
  size_t live;      /* blocks not yet freed */
} chunk_t;

struct qk__mesh_arena {
  chunk_t *c;
  size_t n, cap;
  int sealed;
};

/* Whether the mesher takes its large blocks from an arena when the caller gives no
 * allocator: only where chunks get huge pages. */
int qk__mesh_arena_available(void) { return ARENA_ON; }

qk__mesh_arena_t *qk__mesh_arena_new(void) {
  qk__mesh_arena_t *r = calloc(1, sizeof *r);
  return r;
}

#if ARENA_ON
/* The kept chunks: mappings of whole CHUNKs, oldest first, KEEP_BYTES at most. */
#define KEEP_BYTES ((size_t)64 << 20)
#define KEEP_SLOTS 64
static struct {
  char *base;
  size_t size;
} keep[KEEP_SLOTS];
static size_t keep_n, keep_bytes;
static atomic_flag keep_lock = ATOMIC_FLAG_INIT;

static int keep_take(void) {
  return !atomic_flag_test_and_set_explicit(&keep_lock, memory_order_acquire);
}
static void keep_give(void) { atomic_flag_clear_explicit(&keep_lock, memory_order_release); }

/* The oldest kept mapping unmapped and dropped (lock held). */
static void keep_drop_oldest(void) {
  munmap(keep[0].base, keep[0].size);
  keep_bytes -= keep[0].size;
  memmove(keep, keep + 1, --keep_n * sizeof *keep);
}

/* `size` bytes from the smallest kept mapping that holds them, or NULL. */
static char *keep_get(size_t size) {
  if (!keep_take()) return NULL;
  size_t best = keep_n;
  for (size_t i = 0; i < keep_n; i++)
    if (keep[i].size >= size && (best == keep_n || keep[i].size < keep[best].size)) best = i;
  char *p = NULL;
  if (best < keep_n) {
    p = keep[best].base;
    keep_bytes -= size;
    if (keep[best].size > size)
      keep[best].base += size, keep[best].size -= size;
    else
      memmove(keep + best, keep + best + 1, (--keep_n - best) * sizeof *keep);
  }
  keep_give();
  return p;
}

/* Keep a mapping for later arenas; 0 when it is not kept (too large, or the lock taken). */
static int keep_put(char *base, size_t size) {
  if (size > KEEP_BYTES || !keep_take()) return 0;
  while (keep_n && (keep_n == KEEP_SLOTS || keep_bytes + size > KEEP_BYTES)) keep_drop_oldest();
  keep[keep_n].base = base, keep[keep_n].size = size;
  keep_n++, keep_bytes += size;
  keep_give();
  return 1;
}

void qk_mesh_trim(void) {
  if (!keep_take()) return; /* another thread is at the cache: it stays as it is */
  while (keep_n) keep_drop_oldest();
  keep_give();
}

size_t qk__mesh_arena_kept_bytes(void) {
  if (!keep_take()) return 0;
  size_t n = keep_bytes;
  keep_give();
  return n;
}

void qk__mesh_arena_poison_kept(unsigned char byte) {
  if (!keep_take()) return;
  for (size_t i = 0; i < keep_n; i++) memset(keep[i].base, byte, keep[i].size);
  keep_give();
}

/* A mapping of `size` bytes (a multiple of CHUNK) aligned to CHUNK, marked for huge pages;
 * NULL when the kernel refuses. */
static char *map_chunk(size_t size) {
  char *k = keep_get(size);
  if (k) return k;
  char *p = mmap(NULL, size + CHUNK, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return NULL;
  uintptr_t a = ((uintptr_t)p + CHUNK - 1) & ~(uintptr_t)(CHUNK - 1);
  size_t head = (size_t)(a - (uintptr_t)p);
  if (head) munmap(p, head);
  munmap((char *)a + size, CHUNK - head);
  (void)madvise((void *)a, size, MADV_HUGEPAGE); /* a hint; a refusal leaves 4 KB pages */
  return (char *)a;
}

static void unmap_chunk(chunk_t *c) {
  if (!keep_put(c->base, c->size)) munmap(c->base, c->size);
}
#else
/* Elsewhere (and under AddressSanitizer) the mesher does not use the arena; its chunks
 * come from malloc so that the tests still run its bookkeeping. */
static char *map_chunk(size_t size) { return malloc(size); }
static void unmap_chunk(chunk_t *c) { free(c->base); }
void qk_mesh_trim(void) {}
size_t qk__mesh_arena_kept_bytes(void) { return 0; }
void qk__mesh_arena_poison_kept(unsigned char byte) { (void)byte; }
#endif

void qk__mesh_arena_free(qk__mesh_arena_t *r) {
  if (!r) return;
  for (size_t i = 0; i < r->n; i++) unmap_chunk(&r->c[i]);
  free(r->c);
  free(r);
}

void qk__mesh_arena_seal(qk__mesh_arena_t *r) {
  if (r) r->sealed = 1;
}

static size_t round_up(size_t n, size_t to) { return (n + to - 1) / to * to; }

/* The chunk holding p, or NULL for a block of libc's. */
static chunk_t *chunk_of(qk__mesh_arena_t *r, const void *p) {
  for (size_t i = 0; i < r->n; i++)
    if ((const char *)p >= r->c[i].base && (const char *)p < r->c[i].base + r->c[i].size)
      return &r->c[i];
  return NULL;
}

/* A new block of n bytes from some chunk's top, or from a new chunk; NULL when out of
 * memory. */
static void *arena_get(qk__mesh_arena_t *r, size_t n) {
  size_t need = round_up(n, ALIGN);
  if (need < n) return NULL;
  for (size_t i = r->n; i-- > 0;) {
    chunk_t *c = &r->c[i];
    if (c->size - c->top >= need) {
      void *p = c->base + c->top;
      c->top += need, c->live++;
      return p;
    }
  }
  if (r->n == r->cap) {
    size_t nc = r->cap ? 2 * r->cap : 8;
    chunk_t *c = realloc(r->c, nc * sizeof *c);
    if (!c) return NULL;
    r->c = c, r->cap = nc;
  }
  size_t size = round_up(need, CHUNK);
  if (size < need) return NULL;
  char *base = map_chunk(size);
  if (!base) return NULL;
  /* A block of a chunk or more has its chunk to itself, which goes when it does. */
  r->c[r->n++] = (chunk_t){base, size, need >= CHUNK ? size : need, 1};
  return base;
}

/* Free block p of n bytes in chunk c: a block at the top is taken back; a chunk with no
 * blocks left is emptied, and unmapped unless it is the last (reused next). */
static void arena_put(qk__mesh_arena_t *r, chunk_t *c, char *p, size_t n) {
  c->live--;
  if (r->sealed) return;
  if (p + round_up(n, ALIGN) == c->base + c->top) c->top = (size_t)(p - c->base);
  if (c->live) return;
  c->top = 0;
  if (c == &r->c[r->n - 1] && c->size == CHUNK) return;
  unmap_chunk(c);
  *c = r->c[--r->n];
}

void *qk__mesh_arena_fn(void *ud, void *ptr, size_t osize, size_t nsize) {
  qk__mesh_arena_t *r = ud;
  chunk_t *c = ptr ? chunk_of(r, ptr) : NULL;
  if (!c) {
    /* libc's block (or none): it stays with libc unless it grows to ARENA_MIN. */
    if (nsize == 0) {
      free(ptr);
      return NULL;
    }
    if (r->sealed || nsize < ARENA_MIN) return realloc(ptr, nsize);
    void *q = arena_get(r, nsize);
    if (q && ptr) memcpy(q, ptr, osize < nsize ? osize : nsize), free(ptr);
    return q;
  }
  char *p = ptr;
  if (nsize == 0) {
    arena_put(r, c, p, osize);
    return NULL;
  }
  if (nsize <= osize && (r->sealed || p + round_up(osize, ALIGN) != c->base + c->top))
    return p; /* shrinks in place; the tail is lost until the chunk empties */
  if (!r->sealed && p == c->base && c->top == c->size && c->live == 1 && nsize <= c->size)
    return p; /* a block alone in its chunk, within the chunk */
  if (!r->sealed && p + round_up(osize, ALIGN) == c->base + c->top &&
      (size_t)(p - c->base) + round_up(nsize, ALIGN) <= c->size &&
      round_up(nsize, ALIGN) >= nsize) {
    c->top = (size_t)(p - c->base) + round_up(nsize, ALIGN); /* the top block, in place */
    return p;
  }
  void *q = r->sealed || nsize < ARENA_MIN ? malloc(nsize) : arena_get(r, nsize);
  if (!q) return NULL;
  memcpy(q, p, osize < nsize ? osize : nsize);
  c = chunk_of(r, p); /* arena_get may have moved the chunk records */
  arena_put(r, c, p, osize);
  return q;
}
