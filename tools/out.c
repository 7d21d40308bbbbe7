/* The atomic output writer: a temporary file renamed over the target on success. */
#define _XOPEN_SOURCE 700
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli.h"

/* The regular files this process reads (device and inode), so that an output naming one
 * of them is refused: `-o points.csv` or `--svg points.csv` replaced the input after
 * reading it, without a word. */
static struct {
  dev_t dev;
  ino_t ino;
  const char *path;
} inputs[16];
static size_t n_inputs;

static void note_stat(const char *path, const struct stat *st) {
  if (!S_ISREG(st->st_mode) || n_inputs == sizeof inputs / sizeof *inputs) return;
  inputs[n_inputs].dev = st->st_dev, inputs[n_inputs].ino = st->st_ino;
  inputs[n_inputs++].path = path;
}

void cli_note_input(const char *path) {
  struct stat st;
  if (path && strcmp(path, "-") && stat(path, &st) == 0) note_stat(path, &st);
}

FILE *cli_open_input(const char *cmd, const char *path) {
  FILE *f = fopen(path, "rb");
  const char *why = f ? NULL : strerror(errno), *what = "cannot open";
  struct stat st;
  if (f && fstat(fileno(f), &st) == 0 && S_ISDIR(st.st_mode)) {
    why = "it is a directory", what = "cannot read";
    fclose(f);
    f = NULL;
  }
  if (f && fstat(fileno(f), &st) == 0) note_stat(path, &st);
  if (!f) cli_msg("quadkit%s%s: %s: %s: %s\n", cmd ? " " : "", cmd ? cmd : "", path, what, why);
  return f;
}

/* The outputs open now, by canonical name (the directory's real path and the file name):
 * two outputs of one command naming one file (`-o x --svg x`, or `./x` and `x`) would
 * leave whichever was renamed last, the other lost without a word. */
static const char *open_keys[16];
static size_t n_open;

static char *out_key(const char *final) {
  const char *slash = strrchr(final, '/'), *base = slash ? slash + 1 : final;
  size_t dlen = slash ? (slash == final ? 1 : (size_t)(slash - final)) : 1;
  char *dir = malloc(dlen + 1);
  if (!dir) return NULL;
  memcpy(dir, slash ? final : ".", dlen);
  dir[dlen] = '\0';
  char *real = realpath(dir, NULL), *key = NULL;
  free(dir);
  if (real && (key = malloc(strlen(real) + strlen(base) + 2))) sprintf(key, "%s/%s", real, base);
  free(real);
  return key;
}

static void forget_key(const char *key) {
  for (size_t i = 0; key && i < n_open; i++)
    if (open_keys[i] == key) {
      open_keys[i] = open_keys[--n_open];
      break;
    }
}

/* The temporaries being written, removed by a signal that ends the process (Ctrl-C, a
 * `timeout` or `kill`): outputs are opened before the work, so that an unwritable path
 * fails at once, and a mesh killed while it read or meshed left PREFIX.node.tmp.PID.0
 * and the like behind. Each entry is set once its string is whole and cleared only after
 * the file was renamed or removed (a signal between the two unlinks a name no longer
 * there, which does no harm). */
static const char *volatile live_tmp[16];

static void remove_temporaries(int sig) {
  for (size_t i = 0; i < sizeof live_tmp / sizeof *live_tmp; i++)
    if (live_tmp[i]) unlink(live_tmp[i]); /* (async-signal-safe) */
  signal(sig, SIG_DFL);
  raise(sig); /* the status the signal gives, as if unhandled */
}

static void track_tmp(const char *tmp) {
  static int installed;
  if (!installed) {
    installed = 1;
    static const int sigs[] = {SIGINT, SIGTERM, SIGHUP};
    for (size_t i = 0; i < sizeof sigs / sizeof *sigs; i++) {
      struct sigaction sa, old;
      memset(&sa, 0, sizeof sa);
      sa.sa_handler = remove_temporaries;
      sigemptyset(&sa.sa_mask);
      /* A signal the caller ignores (nohup's SIGHUP) stays ignored. */
      if (sigaction(sigs[i], NULL, &old) == 0 && old.sa_handler != SIG_IGN)
        sigaction(sigs[i], &sa, NULL);
    }
  }
  for (size_t i = 0; i < sizeof live_tmp / sizeof *live_tmp; i++)
    if (!live_tmp[i]) {
      live_tmp[i] = tmp;
      return;
    }
}

static void untrack_tmp(const char *tmp) {
  for (size_t i = 0; i < sizeof live_tmp / sizeof *live_tmp; i++)
    if (live_tmp[i] == tmp) live_tmp[i] = NULL;
}

int cli_out_open(const char *cmd, const char *path, cli_out_t *o) {
  memset(o, 0, sizeof *o);
  if (!*path) { /* (it wrote ".tmp.PID.0" and failed renaming it to "", exit 3) */
    cli_error(cmd, "an output file name is empty ('')");
    return CLI_USAGE;
  }
  if (!strcmp(path, "-")) {
    o->f = stdout;
    return CLI_OK;
  }
  /* A symbolic link is written through: the temporary goes beside its target and is
   * renamed over the target, so the link stays. Something that is not a regular file (a
   * FIFO, a device such as /dev/stdout) cannot be replaced atomically and must not be
   * replaced at all: it is written directly. */
  char *target = NULL;
  struct stat st;
  if (lstat(path, &st) == 0 && S_ISLNK(st.st_mode)) target = realpath(path, NULL);
  const char *final = target ? target : path;
  if (stat(final, &st) == 0 && !S_ISREG(st.st_mode)) {
    o->f = fopen(final, "wb");
    free(target);
    if (!o->f) {
      cli_error(cmd, "cannot write %s: %s", path, strerror(errno));
      return CLI_BAD_INPUT;
    }
    o->direct = 1;
    o->path = strdup(path); /* (for the message when a write fails) */
    return CLI_OK;
  }
  if (stat(final, &st) == 0)
    for (size_t i = 0; i < n_inputs; i++)
      if (st.st_dev == inputs[i].dev && st.st_ino == inputs[i].ino) {
        free(target);
        cli_error(cmd, "cannot write %s: it is the input file %s, which it would replace", path,
                  inputs[i].path);
        return CLI_USAGE;
      }
  o->key = out_key(final);
  for (size_t i = 0; o->key && i < n_open; i++)
    if (!strcmp(o->key, open_keys[i])) {
      free(target);
      free(o->key);
      o->key = NULL;
      cli_error(cmd, "cannot write %s: another output of this command writes that file too", path);
      return CLI_USAGE;
    }
  if (o->key && n_open < sizeof open_keys / sizeof *open_keys) open_keys[n_open++] = o->key;
  size_t n = strlen(final) + 32;
  o->path = strdup(final);
  o->tmp = malloc(n);
  free(target);
  if (!o->path || !o->tmp) {
    free(o->path);
    free(o->tmp);
    forget_key(o->key);
    free(o->key);
    cli_error(cmd, "out of memory");
    return CLI_INTERNAL;
  }
  /* One temporary per output of this process, even when two names reach one file. */
  static unsigned serial;
  snprintf(o->tmp, n, "%s.tmp.%ld.%u", o->path, (long)getpid(), serial++);
  track_tmp(o->tmp); /* (before it exists: a signal in between unlinks nothing) */
  o->f = fopen(o->tmp, "wb");
  if (!o->f) {
    untrack_tmp(o->tmp);
    /* The output is written beside its path first: that file may fail where the path
     * itself exists (-o /proc/version said "No such file or directory"). */
    cli_error(cmd, "cannot write %s: %s (creating the temporary file %s beside it)", path,
              strerror(errno), o->tmp);
    free(o->path);
    free(o->tmp);
    forget_key(o->key);
    free(o->key);
    memset(o, 0, sizeof *o);
    return CLI_BAD_INPUT;
  }
  return CLI_OK;
}

int cli_out_close(const char *cmd, cli_out_t *o, int ok) {
  int rc = CLI_OK;
  if (!o->f) return CLI_OK;
  if (o->f == stdout) {
    if (fflush(stdout) != 0 || ferror(stdout)) {
      cli_error(cmd, "cannot write standard output: %s", strerror(errno));
      rc = CLI_INTERNAL;
    }
    o->f = NULL;
    return rc;
  }
  if (o->direct) { /* a device or FIFO: nothing to take back, but say that it failed */
    if (ferror(o->f)) rc = CLI_INTERNAL;
    int e = rc ? errno : 0; /* (what the failed write left) */
    if (fclose(o->f) != 0) rc = CLI_INTERNAL, e = errno;
    if (rc)
      cli_error(cmd, "cannot write %s: %s", o->path ? o->path : "the output",
                e ? strerror(e) : "write error");
    free(o->path);
    memset(o, 0, sizeof *o);
    return rc;
  }
  if (ferror(o->f)) ok = 0, rc = CLI_INTERNAL;
  if (fclose(o->f) != 0) ok = 0, rc = CLI_INTERNAL;
  if (ok && rename(o->tmp, o->path) != 0) {
    cli_error(cmd, "cannot rename %s to %s: %s", o->tmp, o->path, strerror(errno));
    ok = 0;
    rc = CLI_INTERNAL;
  }
  if (!ok) {
    remove(o->tmp);
    if (rc == CLI_INTERNAL) cli_error(cmd, "failed writing %s", o->path);
  }
  untrack_tmp(o->tmp);
  free(o->path);
  free(o->tmp);
  forget_key(o->key);
  free(o->key);
  memset(o, 0, sizeof *o);
  return rc;
}
