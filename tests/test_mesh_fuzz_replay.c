/*
 * Test plan: replay the mesh-mode fuzz targets' seed corpus and regression inputs
 * (fuzz/corpus/mesh_dyadic, fuzz/corpus/mesh_general and fuzz/regressions/ of each)
 * through exactly the code the fuzzer runs (fuzz/fuzz_mesh_dyadic.c,
 * fuzz/fuzz_mesh_general.c): no crash, no leak, every refusal with a message, and every
 * mesh passing the cheap invariant checks. An empty corpus fails: a replay of nothing
 * checks nothing.
 */
#define _XOPEN_SOURCE 700 /* opendir, fmemopen */
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qk_test.h"

static const char *replay_current = "";
#define QKF_REPLAY 1
#define QKF_FAIL(...)                                                                              \
  do {                                                                                             \
    print_error("while replaying %s:\n", replay_current);                                          \
    fail_msg(__VA_ARGS__);                                                                         \
  } while (0)
#include "fuzz/fuzz_mesh_dyadic.c"
#include "fuzz/fuzz_mesh_general.c"

/* Replay every file of dir (which may be absent); returns how many. */
static size_t replay_dir(const char *dir, int (*fn)(const uint8_t *, size_t)) {
  DIR *d = opendir(dir);
  if (!d) return 0;
  size_t n = 0;
  struct dirent *e;
  while ((e = readdir(d))) {
    if (e->d_name[0] == '.') continue;
    char path[2048];
    snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
    FILE *f = fopen(path, "rb");
    if (!f) fail_msg("cannot open %s", path);
    unsigned char buf[65536];
    size_t len = fread(buf, 1, sizeof buf, f);
    fclose(f);
    replay_current = path;
    fn(buf, len);
    n++;
  }
  closedir(d);
  return n;
}

static void replay(const char *name, int (*fn)(const uint8_t *, size_t)) {
  const char *src = getenv("QK_SOURCE_DIR");
  if (!src) fail_msg("QK_SOURCE_DIR is not set (run the test through ctest)");
  char dir[1024];
  snprintf(dir, sizeof dir, "%s/fuzz/corpus/%s", src, name);
  size_t seeds = replay_dir(dir, fn);
  snprintf(dir, sizeof dir, "%s/fuzz/regressions/%s", src, name);
  size_t regressions = replay_dir(dir, fn);
  print_message("%s: replayed %zu seeds and %zu regression inputs\n", name, seeds, regressions);
  assert_true(seeds > 0);
}

static void test_mesh_fuzz_replay_dyadic(void **state) {
  (void)state;
  replay("mesh_dyadic", qkf_mesh_dyadic);
}

/* Does qk_mesh_generate() know the general mode yet? */
static int have_general(void) {
  const double xy[] = {0, 0, 1, 0, 0, 1};
  const uint32_t seg[] = {0, 1, 1, 2, 2, 0};
  qk_poly_t *p = NULL;
  qk_mesh_t *m = NULL;
  qk_mesh_error_t err;
  assert_int_equal(qk_poly_from_arrays(xy, 3, seg, 3, NULL, 0, NULL, &p, &err), QK_OK);
  qk_mesh_options_t o;
  qk_mesh_options_init(&o);
  o.mode = QK_MESH_GENERAL;
  qk_status_t st = qk_mesh_generate(p, &o, &m, &err);
  qk_mesh_free(m);
  qk_poly_free(p);
  return !(st == QK_ERR_INVALID && strstr(err.message, "mode"));
}

static void test_mesh_fuzz_replay_general(void **state) {
  (void)state;
  if (!have_general()) {
    print_message("qk_mesh_generate does not know QK_MESH_GENERAL yet: skipped\n");
    skip();
  }
  replay("mesh_general", qkf_mesh_general);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_mesh_fuzz_replay_dyadic),
      cmocka_unit_test(test_mesh_fuzz_replay_general),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
