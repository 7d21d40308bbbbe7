/* qk_tree_check(): verifies every structural invariant of a tree (as p4est_is_valid). */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "index/index_internal.h"
#include "index/textloc.h"

typedef struct checker {
  const qk_tree_t *t;
  char *msg;
  size_t msg_size;
  size_t points_seen;
  size_t live_nodes;
  uint8_t *slot_owned; /* one byte per slot: 1 once a leaf claims it */
  uint8_t *id_seen;    /* one byte per id: 1 once a leaf holds it */
  const uint32_t *map; /* the id map, when it has been made */
} checker_t;

static qk_status_t fail(checker_t *c, const char *fmt, ...) {
  if (c->msg && c->msg_size) {
    va_list ap;
    va_start(ap, fmt);
    qk__vsnprintf(c->msg, c->msg_size, fmt, ap);
    va_end(ap);
  }
  return QK_ERR_CORRUPT;
}

/* The leaf the tree's own descent reaches for (x, y). */
static uint32_t leaf_by_descent(const qk_tree_t *t, double x, double y) {
  uint32_t v = 0;
  qk__geom_t g = {t->root_x, t->root_y, 0};
  while (!qk__is_leaf(&t->nodes[v])) {
    unsigned q = qk__quadrant_of(g.x0, g.y0, t->side[g.depth + 1], x, y);
    v = t->nodes[v].child + q;
    g = qk__child_geom(t, g, q);
  }
  return v;
}

/* Check the subtree of v, of geometry g (computed down the path from the root). */
static qk_status_t check_node(checker_t *c, uint32_t v, qk__geom_t g) {
  const qk_tree_t *t = c->t;
  const qk__node_t *n = &t->nodes[v];
  c->live_nodes++;
  if (!qk__live(t, v)) return fail(c, "node %u is reachable but not live", v);
  if (g.depth > t->max_depth) return fail(c, "node %u deeper than the cap", v);
  if (qk__depth(t, v) != g.depth)
    return fail(c, "node %u: recorded depth %u, but %u below the root", v, qk__depth(t, v),
                g.depth);
  if (qk__is_leaf(n)) {
    if ((uint64_t)n->start + n->room > t->n_slots || n->count > n->room)
      return fail(c, "leaf %u: slot range [%u,+%u) count %u out of bounds", v, n->start, n->room,
                  n->count);
    if (n->count > t->capacity && qk__can_split(t, g))
      return fail(c, "leaf %u holds %u points > capacity %u but can split", v, n->count,
                  t->capacity);
    for (uint32_t i = n->start; i < n->start + n->room; i++) {
      if (c->slot_owned[i]) return fail(c, "slot %u owned by two leaves", i);
      c->slot_owned[i] = 1;
    }
    for (uint32_t i = n->start; i < n->start + n->count; i++) {
      qk_id_t id = t->pid[i];
      if (id >= t->n_ids) return fail(c, "slot %u: id %u was never handed out", i, id);
      if (c->map && c->map[id] != i) return fail(c, "slot %u: id %u not mapped back to it", i, id);
      if (c->id_seen[id]) return fail(c, "id %u stored twice", id);
      c->id_seen[id] = 1;
      /* The point must lie where the tie rules send it at every ancestor: the tree's own
       * descent from the root must reach this leaf. */
      if (leaf_by_descent(t, t->px[i], t->py[i]) != v)
        return fail(c, "point %u (%.17g, %.17g) is not in the quadrants leading to leaf %u", id,
                    t->px[i], t->py[i], v);
    }
    c->points_seen += n->count;
    return QK_OK;
  }
  if (n->child >= t->n_nodes || t->n_nodes - n->child < 4 || n->child % 4 != 1)
    return fail(c, "node %u: child block %u invalid", v, n->child);
  if (!qk__can_split(t, g)) return fail(c, "node %u is split but cannot be", v);
  if (!t->refined && n->count <= t->capacity)
    return fail(c, "node %u holds %u <= capacity points but is not a leaf", v, n->count);
  const qk__block_t *k = qk__block_of(t, n->child);
  if (!k->live || k->parent != v || k->depth != g.depth + 1)
    return fail(c, "node %u: block record of children %u (parent %u, depth %u, live %u) wrong", v,
                n->child, k->parent, k->depth, k->live);
  uint64_t sum = 0;
  for (uint32_t q = 0; q < 4; q++) sum += t->nodes[n->child + q].count;
  if (sum != n->count)
    return fail(c, "node %u: count %u != sum of children %llu", v, n->count,
                (unsigned long long)sum);
  for (uint32_t q = 0; q < 4; q++) {
    qk_status_t st = check_node(c, n->child + q, qk__child_geom(t, g, q));
    if (st) return st;
  }
  return QK_OK;
}

/* The free list: n_free_blocks blocks, each in range and marked free. */
static qk_status_t check_free_list(checker_t *c) {
  const qk_tree_t *t = c->t;
  uint32_t seen = 0;
  for (uint32_t b = t->free_block; b != QK_NONE; b = qk__block_of(t, b)->parent) {
    if (b >= t->n_nodes || b % 4 != 1 || seen >= t->n_free_blocks)
      return fail(c, "free list: block %u out of range or list longer than %u", b,
                  t->n_free_blocks);
    if (qk__block_of(t, b)->live) return fail(c, "free list: block %u is marked live", b);
    seen++;
  }
  if (seen != t->n_free_blocks)
    return fail(c, "free list holds %u blocks, tree says %u", seen, t->n_free_blocks);
  return QK_OK;
}

qk_status_t qk_tree_check(const qk_tree_t *t, char *msg, size_t msg_size) {
  checker_t c = {t, msg, msg_size, 0, 0, NULL, NULL, NULL};
  if (msg && msg_size) msg[0] = '\0';
  if (!t) { /* a missing argument, as every call says it (not a corrupt tree) */
    fail(&c, "NULL tree");
    return QK_ERR_INVALID;
  }
  if (t->n_nodes == 0 || t->n_nodes > t->cap_nodes || (t->n_nodes - 1) % 4 != 0 ||
      (t->n_nodes - 1) / 4 > t->cap_blocks)
    return fail(&c, "node count %u / capacity %u / blocks %u inconsistent", t->n_nodes,
                t->cap_nodes, t->cap_blocks);
  const qk__node_t *r = &t->nodes[0];
  if (r->count != t->n_points)
    return fail(&c, "root count %u != points %zu", r->count, t->n_points);
  if (t->n_slots > t->cap_slots) return fail(&c, "slots used beyond capacity");
  c.map = qk__id_map_if_made(t);
  /* Scratch through the tree's allocator, like every allocation of the library. */
  size_t n_slot_bytes = t->n_slots ? t->n_slots : 1, n_id_bytes = t->n_ids ? t->n_ids : 1;
  c.slot_owned = qk__realloc(&t->alloc, NULL, 0, n_slot_bytes);
  c.id_seen = qk__realloc(&t->alloc, NULL, 0, n_id_bytes);
  if (!c.slot_owned || !c.id_seen) {
    qk__free(&t->alloc, c.slot_owned, n_slot_bytes);
    qk__free(&t->alloc, c.id_seen, n_id_bytes);
    return QK_ERR_NOMEM;
  }
  memset(c.slot_owned, 0, n_slot_bytes);
  memset(c.id_seen, 0, n_id_bytes);
  qk_status_t st = check_free_list(&c);
  if (!st) st = check_node(&c, 0, (qk__geom_t){t->root_x, t->root_y, 0});
  if (!st && c.points_seen != t->n_points)
    st = fail(&c, "leaves hold %zu points, tree says %zu", c.points_seen, t->n_points);
  if (!st) {
    size_t owned = 0;
    for (uint32_t i = 0; i < t->n_slots; i++) owned += c.slot_owned[i];
    if (owned + t->garbage != t->n_slots)
      st = fail(&c, "slots: %zu owned + %u garbage != %u used", owned, t->garbage, t->n_slots);
  }
  if (!st && c.map) {
    size_t mapped = 0;
    for (uint32_t id = 0; id < t->n_ids; id++)
      if (c.map[id] != QK_NONE) {
        if (c.map[id] >= t->n_slots || t->pid[c.map[id]] != id) {
          st = fail(&c, "id %u maps to slot %u which holds another point", id, c.map[id]);
          break;
        }
        mapped++;
      }
    if (!st && mapped != t->n_points)
      st = fail(&c, "%zu ids mapped, %zu points", mapped, t->n_points);
  }
  if (!st && t->n_free_ids > t->n_ids - t->n_points)
    st = fail(&c, "%u free ids, but only %zu ids are not in use", t->n_free_ids,
              (size_t)t->n_ids - t->n_points);
  for (uint32_t i = 0; !st && i < t->n_free_ids; i++) {
    qk_id_t id = t->free_ids[i];
    if (id >= t->n_ids || c.id_seen[id] || (c.map && c.map[id] != QK_NONE))
      st = fail(&c, "free id %u is out of range, stored or listed twice", id);
    else
      c.id_seen[id] = 1; /* catches an id listed twice */
  }
  if (!st && c.live_nodes + 4 * (size_t)t->n_free_blocks != t->n_nodes)
    st = fail(&c, "%zu live nodes + %u free blocks != %u slots", c.live_nodes, t->n_free_blocks,
              t->n_nodes);
  qk__free(&t->alloc, c.slot_owned, n_slot_bytes);
  qk__free(&t->alloc, c.id_seen, n_id_bytes);
  return st;
}
