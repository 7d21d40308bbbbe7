/* The atomic output writer: a temporary file renamed over the target on success. */
#define _XOPEN_SOURCE 700
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cli.h"

/* The files this process reads (device and inode), so that an output naming one of them is
 * refused: `-o points.csv` or `--svg points.csv` replaced the input after reading it,
 * without a word, and an output into the pipe or FIFO being read (`-o /dev/stdin`, `mesh -
 * --poly /dev/stdin`, a FIFO named as input and output) hung or lost the output. Regular
 * files, FIFOs and pipes, and block devices are kept; a terminal, /dev/null and other
 * character devices, and sockets, are read and written independently. */
static struct {
  dev_t dev;
  ino_t ino;
  const char *path;
} inputs[16];
static size_t n_inputs;

/* Whether reading and writing a file of this type at once clash (see inputs). */
static int clashes(const struct stat *st) {
  return S_ISREG(st->st_mode) || S_ISFIFO(st->st_mode) || S_ISBLK(st->st_mode);
}

static void note_stat(const char *path, const struct stat *st) {
  if (!clashes(st) || n_inputs == sizeof inputs / sizeof *inputs) return;
  for (size_t i = 0; i < n_inputs; i++)
    if (inputs[i].dev == st->st_dev && inputs[i].ino == st->st_ino) return;
  inputs[n_inputs].dev = st->st_dev, inputs[n_inputs].ino = st->st_ino;
  inputs[n_inputs++].path = path;
}

void cli_note_input(const char *path) {
  struct stat st;
  if (!path) return;
  if (!strcmp(path, "-")) { /* standard input (mesh -) */
    if (fstat(STDIN_FILENO, &st) == 0) note_stat("<stdin>", &st);
  } else if (stat(path, &st) == 0) {
    note_stat(path, &st);
  }
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

/* An output whose file (st: what its path or standard output leads to) is one of the
 * inputs: a usage error. */
static int input_clash(const char *cmd, const char *shown, const struct stat *st, int replaced) {
  if (!clashes(st)) return CLI_OK;
  for (size_t i = 0; i < n_inputs; i++)
    if (st->st_dev == inputs[i].dev && st->st_ino == inputs[i].ino) {
      cli_error(cmd, "cannot write %s: it is the input file %s, %s", shown, inputs[i].path,
                replaced ? "which it would replace"
                         : "which it reads (writing into it would hang or lose the output)");
      return CLI_USAGE;
    }
  return CLI_OK;
}

/* The outputs open now: by canonical name (the directory's real path and the file name)
 * for a file written through a temporary, and by device and inode for whatever exists
 * already (standard output included): two outputs of one command naming one file (`-o x
 * --svg x`, `./x` and `x`, a hard link, `--svg /dev/stdout` beside `-` or the command's
 * own standard output) would leave whichever was renamed last, the other lost without a
 * word, or write both into one stream. Character devices that are not terminals
 * (/dev/null, /dev/full) take any number of outputs. */
static struct {
  unsigned id;
  const char *key; /* (the cli_out_t's; NULL when it has none) */
  int has_id, std;
  dev_t dev;
  ino_t ino;
} open_outs[16];
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

/* Whether an output (std: standard output; st: its file, NULL when it does not exist yet;
 * tty: it is a terminal; key: its canonical name or NULL) meets one already open: the
 * usage error is said. */
static int output_clash(const char *cmd, const char *shown, int std, const struct stat *st, int tty,
                        const char *key) {
  int exempt = st && S_ISCHR(st->st_mode) && !tty;
  for (size_t i = 0; i < n_open; i++) {
    int same = (std && open_outs[i].std) ||
               (st && !exempt && open_outs[i].has_id && open_outs[i].dev == st->st_dev &&
                open_outs[i].ino == st->st_ino) ||
               (key && open_outs[i].key && !strcmp(key, open_outs[i].key));
    if (same) {
      cli_error(cmd, "cannot write %s: another output of this command writes that file too%s",
                shown, std || open_outs[i].std ? " (standard output)" : "");
      return CLI_USAGE;
    }
  }
  return CLI_OK;
}

/* Record an output as open (o->id names it for forget_output). */
static void remember_output(cli_out_t *o, int std, const struct stat *st) {
  static unsigned ids;
  o->id = ++ids;
  if (n_open == sizeof open_outs / sizeof *open_outs) return;
  open_outs[n_open].id = o->id, open_outs[n_open].key = o->key, open_outs[n_open].std = std;
  open_outs[n_open].has_id = st != NULL;
  if (st) open_outs[n_open].dev = st->st_dev, open_outs[n_open].ino = st->st_ino;
  n_open++;
}

static void forget_output(const cli_out_t *o) {
  for (size_t i = 0; o->id && i < n_open; i++)
    if (open_outs[i].id == o->id) {
      open_outs[i] = open_outs[--n_open];
      break;
    }
}

/* The file a chain of symbolic links ends in, existing or not (realpath fails on a
 * dangling link, whose target is the file to create); malloc'd, or NULL with errno set
 * (ELOOP after 40 links, as the kernel counts). */
static char *follow_links(const char *path) {
  char *cur = strdup(path);
  for (int hops = 0; cur; hops++) {
    struct stat st;
    if (lstat(cur, &st) != 0 || !S_ISLNK(st.st_mode)) return cur;
    if (hops == 40) {
      free(cur);
      errno = ELOOP;
      return NULL;
    }
    char to[4096];
    ssize_t n = readlink(cur, to, sizeof to - 1);
    if (n < 0) return cur; /* (it was a link a moment ago: the open that follows says why) */
    to[n] = '\0';
    const char *slash = strrchr(cur, '/');
    size_t dlen = to[0] == '/' || !slash ? 0 : (size_t)(slash - cur) + 1;
    char *next = malloc(dlen + (size_t)n + 1);
    if (next) memcpy(next, cur, dlen), memcpy(next + dlen, to, (size_t)n + 1);
    free(cur);
    cur = next;
  }
  return NULL; /* (out of memory) */
}

/* The descriptor a path names when it is one of the names of an open descriptor, or a
 * chain of links to one: /dev/stdin, /dev/stdout, /dev/stderr, /dev/fd/N, /proc/self/fd/N
 * and /proc/PID/fd/N of this process; -1 otherwise. Such a path is the descriptor as the
 * shell set it up (`>> log`, a `{ ...; } > file` group), not the file it leads to: resolved
 * to that file and replaced, `-o /dev/stdout >> a.csv` lost a.csv's earlier lines. */
static int named_descriptor(const char *path) {
  char cur[4096], to[4096];
  if (strlen(path) >= sizeof cur) return -1;
  strcpy(cur, path);
  for (int hops = 0; hops < 40; hops++) {
    static const char *const std[3] = {"/dev/stdin", "/dev/stdout", "/dev/stderr"};
    for (int k = 0; k < 3; k++)
      if (!strcmp(cur, std[k])) return k;
    char self[64];
    snprintf(self, sizeof self, "/proc/%ld/fd/", (long)getpid());
    const char *const dirs[3] = {"/dev/fd/", "/proc/self/fd/", self};
    for (int k = 0; k < 3; k++) {
      size_t n = strlen(dirs[k]);
      if (strncmp(cur, dirs[k], n) || !cur[n]) continue;
      char *end;
      errno = 0;
      long fd = strtol(cur + n, &end, 10);
      if (*end || errno || fd < 0 || fd > 1 << 20 || cur[n] < '0' || cur[n] > '9') return -1;
      return (int)fd;
    }
    struct stat st;
    if (lstat(cur, &st) != 0 || !S_ISLNK(st.st_mode)) return -1;
    ssize_t n = readlink(cur, to, sizeof to - 1);
    if (n < 0) return -1;
    to[n] = '\0';
    const char *slash = strrchr(cur, '/');
    size_t dlen = to[0] == '/' || !slash ? 0 : (size_t)(slash - cur) + 1;
    if (dlen + (size_t)n >= sizeof cur) return -1;
    memmove(cur + dlen, to, (size_t)n + 1);
  }
  return -1;
}

/* The temporaries being written, removed by a signal that ends the process (Ctrl-C, a
 * `timeout` or `kill`, a reader that closed its pipe): outputs are opened before the work,
 * so that an unwritable path fails at once, and a mesh killed while it read or meshed left
 * PREFIX.node.tmp.PID.0 and the like behind. Each entry is set once its string is whole and
 * cleared only after the file was renamed or removed (a signal between the two unlinks a
 * name no longer there, which does no harm). */
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
    /* (SIGPIPE: a reader that stopped early, `--svg /dev/stdout | head`, left the other
     * outputs' temporaries) */
    static const int sigs[] = {SIGINT, SIGTERM, SIGHUP, SIGPIPE};
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
  struct stat st;
  int rc;
  if (!strcmp(path, "-")) {
    const int have = fstat(STDOUT_FILENO, &st) == 0;
    if (have && (rc = input_clash(cmd, "standard output", &st, 0))) return rc;
    if ((rc = output_clash(cmd, "standard output (-)", 1, have ? &st : NULL, isatty(STDOUT_FILENO),
                           NULL)))
      return rc;
    o->f = stdout;
    remember_output(o, 1, have ? &st : NULL);
    return CLI_OK;
  }
  /* Whatever the path leads to (through links, /dev/stdin, /proc/self/fd/N) must not be
   * an input. */
  if (stat(path, &st) == 0 && (rc = input_clash(cmd, path, &st, S_ISREG(st.st_mode)))) return rc;
  /* A name of an open descriptor (-o /dev/stdout): written through a copy of the
   * descriptor, where it stands and as it was opened (appending, say), never replaced. */
  const int fd = named_descriptor(path);
  if (fd >= 0) {
    const int same_as_stdout = fd == STDOUT_FILENO;
    const int dup_fd = fcntl(fd, F_DUPFD_CLOEXEC, 3);
    if (dup_fd < 0 || fstat(dup_fd, &st) != 0 || !(o->f = fdopen(dup_fd, "wb"))) {
      int e = errno;
      if (dup_fd >= 0) close(dup_fd);
      cli_error(cmd, "cannot write %s: %s", path, strerror(e));
      return CLI_BAD_INPUT;
    }
    if ((rc = output_clash(cmd, path, same_as_stdout, &st, isatty(dup_fd), NULL))) {
      fclose(o->f);
      o->f = NULL;
      return rc;
    }
    o->direct = 1;
    o->path = strdup(path); /* (for the message when a write fails) */
    remember_output(o, same_as_stdout, &st);
    return CLI_OK;
  }
  /* A symbolic link is written through: the temporary goes beside its target and is
   * renamed over the target, so the link stays (a dangling link: its target is created).
   * Something that is not a regular file (a FIFO, a device such as /dev/stdout) cannot
   * be replaced atomically and must not be replaced at all: it is written directly. */
  char *target = NULL;
  if (lstat(path, &st) == 0 && S_ISLNK(st.st_mode)) {
    target = realpath(path, NULL);
    /* (a link that leads somewhere realpath cannot name, /dev/stdout to a pipe, is
     * written through as it stands) */
    if (!target && stat(path, &st) != 0 && !(target = follow_links(path))) {
      cli_error(cmd, "cannot write %s: %s", path, strerror(errno));
      return errno == ENOMEM ? CLI_INTERNAL : CLI_BAD_INPUT;
    }
  }
  const char *final = target ? target : path;
  const int exists = stat(final, &st) == 0;
  if (exists && !S_ISREG(st.st_mode)) {
    /* (a FIFO is checked before it is opened, which waits for a reader; a character
     * device after, to ask whether it is a terminal) */
    if (!S_ISCHR(st.st_mode) && (rc = output_clash(cmd, path, 0, &st, 0, NULL))) {
      free(target);
      return rc;
    }
    o->f = fopen(final, "wb");
    free(target);
    if (!o->f) {
      cli_error(cmd, "cannot write %s: %s", path, strerror(errno));
      return CLI_BAD_INPUT;
    }
    if (S_ISCHR(st.st_mode) && (rc = output_clash(cmd, path, 0, &st, isatty(fileno(o->f)), NULL))) {
      fclose(o->f);
      o->f = NULL;
      return rc;
    }
    o->direct = 1;
    o->path = strdup(path); /* (for the message when a write fails) */
    remember_output(o, 0, &st);
    return CLI_OK;
  }
  o->key = out_key(final);
  if ((rc = output_clash(cmd, path, 0, exists ? &st : NULL, 0, o->key))) {
    free(target);
    free(o->key);
    o->key = NULL;
    return rc;
  }
  size_t n = strlen(final) + 32;
  o->path = strdup(final);
  o->tmp = malloc(n);
  free(target);
  if (!o->path || !o->tmp) {
    free(o->path);
    free(o->tmp);
    free(o->key);
    memset(o, 0, sizeof *o);
    cli_error(cmd, "out of memory");
    return CLI_INTERNAL;
  }
  /* A file the user may not write is not replaced either (the directory's permission is
   * what renaming needs: a read-only file of another user was replaced). */
  if (exists && access(o->path, W_OK) != 0) {
    cli_error(cmd, "cannot write %s: %s", path, strerror(errno));
    free(o->path);
    free(o->tmp);
    free(o->key);
    memset(o, 0, sizeof *o);
    return CLI_BAD_INPUT;
  }
  /* One temporary per output of this process, even when two names reach one file. It is
   * created new, never through a link or over a file already there (a link planted at
   * that name had its target overwritten): a name taken is passed over for the next. */
  static unsigned serial;
  int tfd = -1;
  for (int tries = 0; tfd < 0 && tries < 100; tries++) {
    snprintf(o->tmp, n, "%s.tmp.%ld.%u", o->path, (long)getpid(), serial++);
    track_tmp(o->tmp); /* (before it exists: a signal in between unlinks nothing) */
    tfd = open(o->tmp, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
    if (tfd < 0) untrack_tmp(o->tmp);
    if (tfd < 0 && errno != EEXIST) break;
  }
  /* The file replaced keeps its permissions and, where this process may set them, its
   * owner and group (a 0600 file became 0644). */
  if (tfd >= 0 && exists) {
    if (fchown(tfd, st.st_uid, st.st_gid) != 0 && fchown(tfd, (uid_t)-1, st.st_gid) != 0) {
      /* (not the owner's: the new file is this user's, as any file it writes) */
    }
    (void)fchmod(tfd, st.st_mode & 0777);
  }
  o->f = tfd >= 0 ? fdopen(tfd, "wb") : NULL;
  if (!o->f) {
    int e = errno;
    if (tfd >= 0) {
      close(tfd);
      remove(o->tmp);
      untrack_tmp(o->tmp);
    }
    errno = e;
    /* The output is written beside its path first: that file may fail where the path
     * itself exists (-o /proc/version said "No such file or directory"). */
    cli_error(cmd, "cannot write %s: %s (creating the temporary file %s beside it)", path,
              strerror(errno), o->tmp);
    free(o->path);
    free(o->tmp);
    free(o->key);
    memset(o, 0, sizeof *o);
    return CLI_BAD_INPUT;
  }
  remember_output(o, 0, exists ? &st : NULL);
  return CLI_OK;
}

int cli_out_close(const char *cmd, cli_out_t *o, int ok) {
  int rc = CLI_OK;
  if (!o->f) return CLI_OK;
  forget_output(o);
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
  free(o->key);
  memset(o, 0, sizeof *o);
  return rc;
}
