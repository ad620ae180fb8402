/* hrad: the command line, the only part of hrad that prints.
 *
 * Order of work: every option is checked first, before anything is read or written; a bad value
 * is a usage error (one line, exit status 2), with the bounds hr_solver_create checks plus the
 * command line's own (image size, camera, exposure, --emit values, the output directory). Then
 * the scene is loaded (bad input: one line naming file and line, exit status 1), solved with one
 * progress line per iteration, and the outputs are written as one set.
 *
 * The output set. Every file goes into a staging directory beside DIR (PARENT/.DIR.hrad-PID,
 * flock'ed while this run lives, marked by a file .hrad-staging). When all are written, the
 * staging directory takes DIR's place in one step: rename(2) when DIR does not exist, otherwise
 * renameat2(RENAME_EXCHANGE), after which the staging name holds the previous DIR and is emptied.
 * So DIR holds, at every moment, either the complete previous set or the complete new one.
 * DIR/.hrad-outputs lists the files of the set. Files in DIR that are not on the previous list
 * (the user's, or outputs of an hrad without the list) are carried into the new DIR by hard
 * links before the exchange, so they are never missing either; a new output replaces a file of
 * the same name. DIR must hold only files and symbolic links (checked before the solve), must not
 * be a mount point, and must not contain the working directory. A staging directory left by a
 * killed run (SIGKILL, power loss) is cleaned up by the next run into the same DIR. Snapshots
 * (--snapshots) belong to the set; each is also hard-linked into DIR as soon as it is written.
 * If renameat2 is not supported (some network file systems), the files are renamed into DIR one
 * by one, with a warning.
 *
 * Signals. SIGINT, SIGTERM and SIGHUP (each unless it was ignored when hrad started, as for
 * background jobs of scripts and under nohup) are blocked in every thread and taken by one
 * thread with sigwait. The first one asks the solve to stop at the next safe point (the
 * per-iteration callback, or between output files) and prints one line; the run then removes its
 * staging directory and dies by the same signal (exit status 128+N in a shell: 130 for SIGINT,
 * 143 for SIGTERM). A second one removes the staging directory at once (waiting only for a file
 * being written) and dies the same way. Once the commit has begun it is completed first. SIGPIPE
 * is ignored: a closed stderr does not stop a run. */
#include "hrad.h"
#include "output.h"
#include "report.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Limits the command line enforces on top of hr_solver_create's checks (README "Limits"). */
#define MIN_SIDE 16                 /* --size: each side in MIN_SIDE..MAX_SIDE */
#define MAX_SIDE 16384
#define MAX_PIXELS (1L << 26)       /* --size: W*H; the renderer caps 2x2 supersampling at 2^28 */
#define MAX_THREADS 1024            /* --threads (0: all cores) */
#define MIN_EMIT 1e-30              /* --emit: radiosity per channel 0 or in MIN..MAX_EMIT W/m^2 */
#define MAX_EMIT 1e30               /* (the range of MTL Ke, obj.c) */
#define MAX_VERIFY 1e12             /* --verify N */
#define MAX_VERIFY_SPP 1000000      /* --verify-image SPP */
#define CKPT_EVERY 60.0             /* --checkpoint-every default, seconds */

#define MANIFEST ".hrad-outputs"    /* in DIR: the files of the set, one per line */
#define MARKER ".hrad-staging"      /* in a staging directory until its commit */
#define SNAP_TMP ".hrad-snap-"      /* in DIR: a snapshot being linked into place */

/* --outputs: the files of a run that can be chosen */
enum { OUT_CSV = 1, OUT_JSON = 2, OUT_PNG = 4, OUT_PLY = 8, OUT_GLB = 16, OUT_VIEWER = 32 };
static const char *const OUT_NAMES[] = {"csv", "json", "png", "ply", "glb", "viewer", NULL};

typedef struct names {
  char **v;
  int n, cap;
} names;

typedef struct cli {
  hr_options opt;
  int balance_random;     /* --balance random[:SEED] or area (with balance_method none) */
  uint64_t balance_seed;
  int balance_method;     /* --balance none|anneal|metis|orb (HR_BALANCE_*) */
  double balance_alpha, balance_idle;
  const char *dump_graph; /* --dump-graph FILE */
  const char *scene_arg;
  const char *outdir; /* -o as given */
  int quiet;
  int no_progress; /* --no-progress: no progress bar or progress lines */
  int snapshots;
  int snap_collect; /* distributed run with snapshots: collect the leaves each iteration */
  int hdr;
  int have_camera;
  hr_camera camera;
  int w, h;
  double exposure; /* 0 = automatic */
  int nemit, cap_emit;
  char **emit_name;
  double (*emit_rgb)[3];
  const char *ckpt;      /* --checkpoint FILE (NULL: none) */
  double ckpt_every;     /* --checkpoint-every S: seconds between checkpoints */
  double ckpt_last;      /* when the last one was written (or the solve began) */
  int ckpt_iter;         /* the iteration last saved, or tried (0: none) */
  int ckpt_ok;           /* that save succeeded */
  const char *resume;    /* --resume FILE (NULL: none) */
  int64_t verify_paths; /* --verify N: path-traced reference per polygon (0 = off) */
  int verify_spp;       /* --verify-image SPP: path-traced reference image (0 = off) */
  int viewer;           /* three.js is installed: write viewer.html */
  unsigned outputs;     /* --outputs: OUT_* bits of the files to write */
  double scale;         /* --scale S: coordinates times S (1: as read) */
  int cut_contacts;     /* --cut-contacts on|off (hr_scene_cut_contacts at sqrt(A_e)) */
  hr_cut_stats cuts;    /* what it did */
  const char *list_mats; /* --list-materials FILE: print its material names and exit */
  FILE *rep;            /* the --verify reports, shown on stderr once the set is committed (a
                           failed run prints only its one-line error) */
  char *rep_buf;
  size_t rep_len;
  /* the output set */
  char disp[PATH_MAX];        /* DIR for messages: -o without trailing slashes */
  char dir[PATH_MAX];         /* DIR, absolute, symbolic links resolved */
  char parent[PATH_MAX];      /* its parent directory */
  char stage[PATH_MAX + 256]; /* the staging directory; "" once committed or removed */
  int stage_fd;               /* open on the staging directory, holding its flock */
  names outs;                 /* the files written into the staging directory, in order */
  int nsnap;
  /* run state */
  const hr_scene *scene;
  hr_camera cam;
} cli;

static cli *g_cli;                /* for cleanup on errors and signals */
static pthread_mutex_t g_lock;    /* recursive; held while the staging directory changes */
static atomic_int g_stop;         /* the first signal received, 0 if none */
/* MPI (README "Many processes"): NULL in a plain run. Rank 0 prints and writes; the others
 * solve beside it. g_together: every rank runs the same code here (parsing, loading, solving),
 * so an error there is met by all of them at once and they can leave MPI in order; an error in
 * rank 0's own work (outputs) ends it alone, and mpirun then ends the others. */
static hr_dist *g_dist;
static int g_ranks = 1; /* stays when g_dist is finished: a SIGTERM can come after that */
static int g_rank, g_together = 1;

/* Leaves MPI (if in it) and exits. */
static void leave(int code)
#if defined(__GNUC__)
    __attribute__((noreturn))
#endif
    ;
static void leave(int code) {
  if (g_together) hr_dist_finish(&g_dist);
  exit(code);
}
static sigset_t g_sigs;           /* the signals the signal thread takes */

static void lock(void) { pthread_mutex_lock(&g_lock); }
static void unlock(void) { pthread_mutex_unlock(&g_lock); }

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* ---------------------------------------------------------------- progress and warnings */

/* Progress (issue 13). On a terminal, one line redrawn with '\r' (the phase, a bar, the share
 * done, the seconds spent and, past 2% of initial linking, an estimate of those left), erased
 * before any other line is printed and redrawn after it; the per-iteration lines stay as they
 * were. When stderr is not a terminal, a plain line at most every PLAIN_EVERY seconds of a
 * phase, never '\r'. Only rank 0 draws (the others are --quiet); --quiet and --no-progress draw
 * nothing. */
#define PLAIN_EVERY 5.0  /* seconds between plain progress lines */
#define BAR_WIDTH 20
#define PH_WRITE 100     /* the phase after the solve: writing the outputs (no fraction) */

typedef struct progress {
  int tty;         /* stderr is a terminal */
  int phase;       /* HR_PHASE_*, PH_WRITE, or -1 before the first report */
  double t_phase;  /* when the current phase began: the run's start or the previous's end */
  double t_plain;  /* when the last plain line was printed */
  double fraction; /* of the current phase */
  int drawn;       /* the line is to be on the terminal (between reports too) */
  int shown;       /* characters of the line on the terminal now (0: none) */
} progress;

static progress g_prog = {.phase = -1};
static pthread_mutex_t g_out = PTHREAD_MUTEX_INITIALIZER; /* stderr lines vs the progress line */

/* Erases the progress line from the terminal (caller holds g_out). */
static void progress_erase(void) {
  if (!g_prog.shown) return;
  fprintf(stderr, "\r%*s\r", g_prog.shown, "");
  g_prog.shown = 0;
}

static void tty_line(char *out, size_t n, int phase, double fraction, double secs);

/* Draws the progress line of the current phase, as of now (caller holds g_out). */
static void progress_draw(void) {
  if (!g_prog.tty || !g_prog.drawn) return;
  char line[192];
  tty_line(line, sizeof line, g_prog.phase, g_prog.fraction, now_s() - g_prog.t_phase);
  fprintf(stderr, "\r%s", line);
  g_prog.shown = (int)strlen(line);
  fflush(stderr);
}

/* Prints one line "FMT\n" to stderr without garbling the progress line. */
static void say(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;
static void say(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  pthread_mutex_lock(&g_out);
  progress_erase();
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  progress_draw();
  pthread_mutex_unlock(&g_out);
  va_end(ap);
}

/* Ends the progress display: the line is erased and not drawn again. */
static void progress_stop(void) {
  pthread_mutex_lock(&g_out);
  progress_erase();
  g_prog.drawn = 0;
  pthread_mutex_unlock(&g_out);
}

static const char *phase_name(int phase) {
  return phase == HR_PHASE_LINK    ? "initial linking"
         : phase == HR_PHASE_SOLVE ? "refining"
                                   : "writing outputs";
}

/* "12.3 s, about 9 s left" for 'secs' spent on 'fraction' of 'phase'; "12.3 s" alone for the
 * solve, whose share (the BF_e schedule and the convergence at BF_low) is not a share of its
 * time: on the conference room an estimate would have said 5 min left with one to go. */
static void eta_text(char *out, size_t n, int phase, double secs, double fraction) {
  int k = snprintf(out, n, "%.1f s", secs);
  if (k < 0 || (size_t)k >= n || phase == HR_PHASE_SOLVE || !(fraction > 0.02) || fraction >= 1)
    return;
  const double left = secs * (1 - fraction) / fraction;
  if (left < 100)
    snprintf(out + k, n - (size_t)k, ", about %.0f s left", ceil(left));
  else
    snprintf(out + k, n - (size_t)k, ", about %.0f min left", ceil(left / 60));
}

/* The terminal line: "initial linking  [#######.............]  58%  12.3 s, about 9 s left",
 * or for PH_WRITE "writing outputs ...". */
static void tty_line(char *out, size_t n, int phase, double fraction, double secs) {
  if (phase == PH_WRITE) {
    snprintf(out, n, "%s ...", phase_name(phase));
    return;
  }
  char bar[BAR_WIDTH + 1], eta[64];
  const int full = (int)(fraction * BAR_WIDTH);
  for (int i = 0; i < BAR_WIDTH; i++) bar[i] = i < full ? '#' : '.';
  bar[BAR_WIDTH] = 0;
  eta_text(eta, sizeof eta, phase, secs, fraction);
  snprintf(out, n, "%-15s  [%s] %3.0f%%  %s", phase_name(phase), bar, floor(100 * fraction),
           eta);
}

/* The solver's progress callback (hr_progress_fn). */
static void on_progress(void *ud, hr_phase phase, double fraction) {
  (void)ud;
  const double t = now_s();
  pthread_mutex_lock(&g_out);
  if ((int)phase != g_prog.phase) {
    g_prog.phase = (int)phase;
    g_prog.t_plain = g_prog.t_phase;
  }
  const double secs = t - g_prog.t_phase;
  g_prog.fraction = fraction;
  if (g_prog.tty) {
    g_prog.drawn = fraction < 1; /* erased at the end of each phase */
    progress_erase();
    progress_draw();
  } else if (fraction < 1 && t - g_prog.t_plain >= PLAIN_EVERY) {
    char eta[64];
    eta_text(eta, sizeof eta, phase, secs, fraction);
    fprintf(stderr, "hrad: %s %.0f%% (%s)\n", phase_name(phase), floor(100 * fraction),
            eta);
    g_prog.t_plain = t;
  }
  if (fraction >= 1) g_prog.t_phase = t; /* the next phase starts now */
  pthread_mutex_unlock(&g_out);
}

/* Sets up the progress display of solver 's' (rank 0, unless --quiet or --no-progress). */
static void progress_start(hr_solver *s, int show) {
  g_prog.tty = show && isatty(2);
  g_prog.t_phase = now_s();
  if (show) hr_solver_set_progress(s, on_progress, NULL); /* fails only out of memory: no bar */
}

/* On a terminal: "writing outputs ..." until progress_stop. */
static void progress_writing(void) {
  if (!g_prog.tty) return;
  pthread_mutex_lock(&g_out);
  g_prog.phase = PH_WRITE;
  g_prog.drawn = 1;
  progress_erase();
  progress_draw();
  pthread_mutex_unlock(&g_out);
}

/* Repeated warnings. A warning's kind is its text with every run of digits read as one '#',
 * quoted text ('...') as one '*' and parenthesised text left out: "s.obj:15: degenerate polygon
 * skipped (extent 1e-09 below 1e-06)" and "s.obj:230: degenerate polygon skipped" are one kind,
 * warnings about different files are not. The first WARN_SHOWN of a kind are printed; the
 * others are counted, and warn_summary prints one line per kind that had more. */
#define WARN_SHOWN 3
#define WARN_KINDS 256 /* kinds remembered; warnings of later kinds are all printed */

typedef struct warn_kind {
  char *key, *first; /* the kind, and the text of its first warning */
  long n;            /* warnings of this kind so far */
} warn_kind;

static warn_kind g_warn[WARN_KINDS];
static int g_nwarn;

/* The kind of warning 'msg' (see above) into out[n]. */
static void warn_key(const char *msg, char *out, size_t n) {
  size_t k = 0;
  int paren = 0;
  for (const char *p = msg; *p && k + 1 < n; p++) {
    if (*p == '(') paren++;
    else if (*p == ')' && paren > 0) paren--;
    else if (paren) continue;
    else if (*p >= '0' && *p <= '9') {
      while (p[1] >= '0' && p[1] <= '9') p++;
      out[k++] = '#';
    } else if (*p == '\'' && strchr(p + 1, '\'')) {
      p = strchr(p + 1, '\'');
      out[k++] = '*';
    } else {
      out[k++] = *p;
    }
  }
  out[k] = 0;
}

/* The entry of kind 'key' (added if new); NULL when the table is full or memory is short. */
static warn_kind *warn_find(const char *key, const char *msg) {
  for (int i = 0; i < g_nwarn; i++)
    if (!strcmp(g_warn[i].key, key)) return &g_warn[i];
  if (g_nwarn == WARN_KINDS) return NULL;
  warn_kind *w = &g_warn[g_nwarn];
  w->key = strdup(key);
  w->first = strdup(msg);
  w->n = 0;
  if (!w->key || !w->first) {
    free(w->key);
    free(w->first);
    return NULL;
  }
  g_nwarn++;
  return w;
}

/* The loader's warning sink (hr_log_fn). */
static void warn_cb(void *ud, const char *msg) {
  (void)ud;
  char key[512];
  warn_key(msg, key, sizeof key);
  pthread_mutex_lock(&g_out);
  warn_kind *w = warn_find(key, msg);
  const int show = !w || ++w->n <= WARN_SHOWN;
  pthread_mutex_unlock(&g_out);
  if (show) say("hrad: warning: %s", msg);
}

/* For each kind with more than WARN_SHOWN warnings, "hrad: warning: FIRST ... and N more like
 * it"; then forgets them all. */
static void warn_summary(void) {
  pthread_mutex_lock(&g_out);
  const int n = g_nwarn;
  g_nwarn = 0;
  pthread_mutex_unlock(&g_out);
  for (int i = 0; i < n; i++) {
    warn_kind *w = &g_warn[i];
    if (w->n > WARN_SHOWN) say("hrad: warning: %s ... and %ld more like it", w->first,
                               w->n - WARN_SHOWN);
    free(w->key);
    free(w->first);
  }
}

/* Prints "hrad: MSG" and the --help hint, exits with status 2 (before anything was written). */
static void die_usage(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2), noreturn))
#endif
    ;
static void die_usage(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  if (g_rank == 0) {
    fprintf(stderr, "hrad: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\nTry 'hrad --help'.\n");
  }
  va_end(ap);
  leave(2);
}

/* ---------------------------------------------------------------- staging and cleanup */

/* 'a' + '/' + 'b' into out[n]; "" if it does not fit (every use of "" then fails cleanly). */
static char *join(char *out, size_t n, const char *a, const char *b) {
  size_t la = strlen(a), lb = strlen(b);
  if (la + 1 + lb >= n) {
    out[0] = 0;
    return out;
  }
  memcpy(out, a, la);
  out[la] = '/';
  memcpy(out + la + 1, b, lb + 1);
  return out;
}

/* Removes every entry of directory 'path' (files only; it holds no directories) and the
 * directory itself; 1 when it is gone. */
static int rm_flat(const char *path) {
  DIR *d = opendir(path);
  if (d) {
    int fd = dirfd(d);
    struct dirent *e;
    while ((e = readdir(d)))
      if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) unlinkat(fd, e->d_name, 0);
    closedir(d);
  }
  return rmdir(path) == 0 || errno == ENOENT;
}

/* Removes the staging directory (if any) with everything in it. */
static void remove_stage(cli *c) {
  if (!c) return;
  lock();
  if (c->stage[0]) rm_flat(c->stage);
  c->stage[0] = 0;
  if (c->stage_fd >= 0) close(c->stage_fd);
  c->stage_fd = -1;
  unlock();
}

/* Prints "hrad: MSG" (paths inside the staging directory named by their place in DIR), removes
 * the staging directory and exits with status 1. */
static void fail(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2), noreturn))
#endif
    ;
static void fail(const char *fmt, ...) {
  char m[8192], out[8192];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(m, sizeof m, fmt, ap);
  va_end(ap);
  lock();
  cli *c = g_cli;
  const char *p = m;
  size_t k = 0;
  if (c && c->stage[0]) {
    size_t sl = strlen(c->stage);
    for (const char *q; (q = strstr(p, c->stage)) && k < sizeof out;) {
      k += (size_t)snprintf(out + k, sizeof out - k, "%.*s%s", (int)(q - p), p, c->disp);
      p = q + sl;
    }
  }
  if (k < sizeof out) snprintf(out + k, sizeof out - k, "%s", p);
  if (g_rank == 0 || !g_together) {
    warn_summary();
    progress_stop();
    fprintf(stderr, "hrad: %s\n", out);
  }
  remove_stage(c);
  leave(1);
}

/* Fails on an error status. With MPI, every rank meets the errors of the common work together:
 * rank 0 reports them, except that a rank that failed alone (out of memory) reports its own and
 * the others (HR_ERR_REMOTE) stay silent. */
static void check(hr_status st, const hr_err *err) {
  if (st == HR_OK) return;
  if (st == HR_ERR_REMOTE && g_dist) {
    remove_stage(g_cli);
    leave(1);
  }
  if (g_dist && st == HR_ERR_NOMEM) { /* this rank alone */
    fprintf(stderr, "hrad: rank %d: %s\n", g_rank, err->msg);
    remove_stage(g_cli);
    leave(1);
  }
  fail("%s", err->msg);
}

static void *xrealloc(void *p, size_t n) {
  void *q = realloc(p, n ? n : 1);
  if (!q) fail("out of memory");
  return q;
}

static int names_has(const names *l, const char *s) {
  for (int i = 0; i < l->n; i++)
    if (!strcmp(l->v[i], s)) return 1;
  return 0;
}

static void names_add(names *l, const char *s) {
  if (names_has(l, s)) return;
  if (l->n == l->cap) {
    l->cap = l->cap ? 2 * l->cap : 32;
    l->v = xrealloc(l->v, (size_t)l->cap * sizeof *l->v);
  }
  l->v[l->n] = strdup(s);
  if (!l->v[l->n]) fail("out of memory");
  l->n++;
}

static void names_free(names *l) {
  for (int i = 0; i < l->n; i++) free(l->v[i]);
  free(l->v);
  memset(l, 0, sizeof *l);
}

/* Reads the list of a set (DIRPATH/.hrad-outputs: '#' comment lines, then one name per line,
 * with '\' and line breaks escaped as "\\" and "\n", and a leading '#' as "\#") into 'l'; a
 * missing list is empty. */
static void read_manifest(const char *dirpath, names *l) {
  char path[PATH_MAX + 300];
  join(path, sizeof path, dirpath, MANIFEST);
  FILE *f = fopen(path, "r");
  if (!f) return;
  char *line = NULL;
  size_t cap = 0;
  ssize_t n;
  while ((n = getline(&line, &cap, f)) > 0) {
    if (line[n - 1] == '\n') line[--n] = 0;
    if (n == 0 || line[0] == '#') continue;
    size_t k = 0;
    for (ssize_t i = 0; i < n; i++) {
      if (line[i] == '\\' && i + 1 < n) {
        i++;
        line[k++] = line[i] == 'n' ? '\n' : line[i];
      } else {
        line[k++] = line[i];
      }
    }
    line[k] = 0;
    if (!strchr(line, '/') && strcmp(line, ".") && strcmp(line, "..")) names_add(l, line);
  }
  free(line);
  fclose(f);
}

/* Empties 'old', a former DIR (or a staging directory whose marker is gone), and removes it:
 * files on its list 'set' and hrad's own files are deleted, as are hard links of files that DIR
 * holds as well (carried over) and files that an output of DIR's set 'now' replaced; anything
 * else (a file the user added during the exchange) is moved back into DIR unless DIR has that
 * name, in which case 'old' is kept. 1 when 'old' is gone. */
static int tidy_old(const char *old, const char *dir, const names *set, const names *now) {
  DIR *d = opendir(old);
  if (!d) return errno == ENOENT;
  int ofd = dirfd(d), keep = 0;
  struct dirent *e;
  char p[PATH_MAX + 300];
  while ((e = readdir(d))) {
    const char *n = e->d_name;
    if (!strcmp(n, ".") || !strcmp(n, "..")) continue;
    if (!strcmp(n, MANIFEST) || !strcmp(n, MARKER) || !strncmp(n, SNAP_TMP, strlen(SNAP_TMP)) ||
        names_has(set, n)) {
      unlinkat(ofd, n, 0);
      continue;
    }
    struct stat a, b;
    if (fstatat(ofd, n, &a, AT_SYMLINK_NOFOLLOW) != 0) continue;
    join(p, sizeof p, dir, n);
    if (lstat(p, &b) == 0) {
      if ((a.st_dev == b.st_dev && a.st_ino == b.st_ino) || names_has(now, n))
        unlinkat(ofd, n, 0);
      else
        keep = 1;
    } else if (renameat2(ofd, n, AT_FDCWD, p, RENAME_NOREPLACE) != 0) {
      keep = 1;
    }
  }
  closedir(d);
  if (keep) return 0;
  return rmdir(old) == 0 || errno == ENOENT;
}

/* Cleans up staging directories of DIR left by runs that were killed (no process holds their
 * flock): one still marked as staging is deleted; one without the marker was swapped or about
 * to be, and is emptied by tidy_old. */
static void clean_stale(cli *c, const char *base) {
  char prefix[300], p[PATH_MAX + 300];
  snprintf(prefix, sizeof prefix, ".%.200s.hrad-", base);
  size_t pl = strlen(prefix);
  DIR *d = opendir(c->parent);
  if (!d) return;
  struct dirent *e;
  names now = {0};
  read_manifest(c->dir, &now);
  while ((e = readdir(d))) {
    const char *n = e->d_name;
    if (strncmp(n, prefix, pl) || !n[pl] || strspn(n + pl, "0123456789") != strlen(n + pl))
      continue;
    if (strtol(n + pl, NULL, 10) == (long)getpid()) continue;
    join(p, sizeof p, c->parent, n);
    int fd = open(p, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) continue;
    if (flock(fd, LOCK_EX | LOCK_NB) == 0) {
      if (faccessat(fd, MARKER, F_OK, AT_SYMLINK_NOFOLLOW) == 0) {
        rm_flat(p);
      } else {
        names set = {0};
        read_manifest(p, &set);
        tidy_old(p, c->dir, &set, &now);
        names_free(&set);
      }
    }
    close(fd);
  }
  names_free(&now);
  closedir(d);
}

/* The path of output 'name' in the staging directory, registering it as part of the set. */
static const char *stage_file(cli *c, const char *name, char *path, size_t n) {
  names_add(&c->outs, name);
  if (!*join(path, n, c->stage, name)) fail("%s/%s: path too long", c->disp, name);
  return path;
}

/* ---------------------------------------------------------------- signals */

static const char *sig_name(int sig) {
  return sig == SIGINT    ? "SIGINT"
         : sig == SIGTERM ? "SIGTERM"
         : sig == SIGHUP  ? "SIGHUP"
                          : "a signal";
}

/* Ends the process by 'sig' with its default action (so a calling shell sees 128+sig and stops a
 * loop on Ctrl-C); _exit(128+sig) should that not happen. */
static void die_by_signal(int sig) {
  progress_stop();
  fflush(stderr);
  signal(sig, SIG_DFL);
  sigset_t one;
  sigemptyset(&one);
  sigaddset(&one, sig);
  raise(sig);
  pthread_sigmask(SIG_UNBLOCK, &one, NULL);
  _exit(128 + sig);
}

/* The signal thread: the first signal asks the run to stop, the second ends it at once. */
static void *sig_thread(void *arg) {
  (void)arg;
  for (int n = 0;; n++) {
    int sig;
    if (sigwait(&g_sigs, &sig) != 0) continue;
    if (n == 0) {
      atomic_store(&g_stop, sig);
      /* mpirun passes a signal to every rank: one line, from rank 0; and a SIGTERM under
       * mpirun is mpirun ending the job after another rank failed, which that rank reported */
      if (g_rank == 0 && !(g_ranks > 1 && sig == SIGTERM))
        say("hrad: interrupted by %s: stopping without writing outputs (once more to stop at "
            "once)",
            sig_name(sig));
      continue;
    }
    lock(); /* not while a file is being written or the set is being committed */
    remove_stage(g_cli);
    die_by_signal(sig);
  }
  return NULL;
}

/* Blocks SIGINT, SIGTERM and SIGHUP (those not ignored) in this and every later thread and
 * starts the thread that takes them; ignores SIGPIPE. */
static void start_signals(void) {
  const int sigs[] = {SIGINT, SIGTERM, SIGHUP};
  sigemptyset(&g_sigs);
  for (int i = 0; i < 3; i++) {
    struct sigaction old;
    if (sigaction(sigs[i], NULL, &old) == 0 && old.sa_handler != SIG_IGN)
      sigaddset(&g_sigs, sigs[i]);
  }
  signal(SIGPIPE, SIG_IGN);
  pthread_sigmask(SIG_BLOCK, &g_sigs, NULL);
  pthread_t th;
  pthread_attr_t at;
  pthread_attr_init(&at);
  pthread_attr_setdetachstate(&at, PTHREAD_CREATE_DETACHED);
  pthread_attr_setstacksize(&at, 1 << 18);
  if (pthread_create(&th, &at, sig_thread, NULL) != 0)
    pthread_sigmask(SIG_UNBLOCK, &g_sigs, NULL); /* no thread: the default actions apply */
  pthread_attr_destroy(&at);
}

/* A safe point: after a signal, removes the staging directory and ends the run. */
static void check_stop(cli *c) {
  int sig = atomic_load(&g_stop);
  if (!sig) return;
  lock();
  remove_stage(c);
  die_by_signal(sig);
}

/* ---------------------------------------------------------------- options */

/* The built-in scene names, comma-separated, in 'out'; "hall" is shown as "hall[:N]". */
static void scene_list(char *out, size_t size) {
  out[0] = '\0';
  for (const char *const *n = hr_scene_builtin_names(); *n; n++)
    snprintf(out + strlen(out), size - strlen(out), "%s%s%s", out[0] ? ", " : "", *n,
             strcmp(*n, "hall") ? "" : "[:N]");
}

static void usage(void) {
  hr_options d;
  hr_options_default(&d);
  char scenes[256];
  scene_list(scenes, sizeof scenes);
  printf(
      "Usage: hrad [OPTIONS] [--] [SCENE]\n"
      "Hierarchical radiosity (Bohn & Garmann, WSCG'95). SCENE is a built-in name\n"
      "(%s; default room)\n"
      "or a scene file, read by its extension: .obj (with its .mtl), or through assimp\n"
      ".gltf .glb .ply .3ds .fbx .dae .stl. hall:N, for scaling runs, is N x N furnished\n"
      "cells of small triangles, 991 N^2 + 70 N of them (N in 1..64; hall is hall:4; its\n"
      "files are named hall-N).\n"
      "\n"
      "Output (written as one set: DIR holds the complete previous or the complete new set):\n"
      "  -o, --out DIR        output directory (default hrad-out): surfaces.csv, stats.json,\n"
      "                       SCENE.png, SCENE-elements.png, SCENE.ply, SCENE.glb, viewer.html;\n"
      "                       other files in DIR are kept, subdirectories are refused\n"
      "  --outputs LIST       write only these, comma-separated: csv (surfaces.csv), json\n"
      "                       (stats.json), png (SCENE.png, SCENE-elements.png), ply, glb,\n"
      "                       viewer (default: all)\n"
      "  --size WxH           image size (default 800x600): each side %d..%d, at most\n"
      "                       %ld pixels\n"
      "  --camera E:A[:FOV]   camera eye and look-at point, 'ex,ey,ez:ax,ay,az[:fov]' (degrees,\n"
      "                       1 < fov < 179, default 50)\n"
      "  --exposure X         linear exposure factor > 0 (default: automatic)\n"
      "  --hdr                also write SCENE.pfm (linear radiosity image)\n"
      "  --snapshots          write DIR/iter-NN.png after every iteration while solving\n"
      "  --quiet              no progress lines, warnings or timing table\n"
      "  --no-progress        no progress bar (on a terminal) or progress lines with the\n"
      "                       time left (otherwise, every 5 s); the iteration lines stay\n"
      "\n"
      "Checkpoints (README 'Long runs'):\n"
      "  --checkpoint FILE    save the solver's state to FILE (atomically: a kill leaves the\n"
      "                       previous one whole) after an iteration when --checkpoint-every\n"
      "                       seconds have passed since the last, when a signal stops the run,\n"
      "                       and at the end\n"
      "  --checkpoint-every S seconds between checkpoints (>= 0, default %g; 0: every iteration)\n"
      "  --resume FILE        continue from a checkpoint of the same scene and solver options\n"
      "                       (--threads may differ); the result is the one an uninterrupted\n"
      "                       run gives, bit for bit. From a finished run's checkpoint only the\n"
      "                       outputs are written (e.g. other --camera or --size)\n"
      "\n"
      "Many processes (mpirun -np P hrad ..., README 'Many processes'):\n"
      "  --balance anneal|metis|orb|none  start with whole surfaces split by space (clustered\n"
      "                       runs: compact pieces of the hierarchy), then balance the patch/link\n"
      "                       graph, clusters included, after initial linking and whenever an\n"
      "                       iteration's idle time passes --balance-idle: simulated\n"
      "                       annealing (the paper's 2.2.5; the default), METIS, or\n"
      "                       recursive bisection; none: keep the start\n"
      "  --balance random[:N] every element, at any depth, to a rank drawn from its id and N\n"
      "                       (N = 1 when not given), never moved\n"
      "  --balance area       whole surfaces to ranks by area, largest first, never moved\n"
      "                       (the answer is the same for every assignment)\n"
      "  --balance-alpha A    weight of communication against work in the cost (0.5)\n"
      "  --balance-idle X     idle fraction that triggers balancing (0.1); 0: every\n"
      "                       third iteration, whatever it costs (tests, experiments)\n"
      "  --dump-graph FILE    write the final patch/link graph (nodes, weights, edges)\n"
      "\n"
      "Checking (an independent Monte Carlo path tracer, README 'Checking the light'):\n"
      "  --verify N           after solving, estimate every polygon with N paths, print a\n"
      "                       per-polygon comparison and the area-weighted RMS error, write\n"
      "                       DIR/verify.csv\n"
      "  --verify-image SPP   path-trace the image at SPP samples per pixel, write\n"
      "                       DIR/SCENE-reference.png and print the mean per-pixel error\n"
      "\n"
      "Scene:\n"
      "  --emit NAME=R,G,B    make material NAME emit radiosity R,G,B (W/m^2: 0 or %g..%g);\n"
      "                       repeatable; or NAME=60W (the radiant power of all its polygons\n"
      "                       together) or NAME=800lm (their luminous flux, at 683 lm/W), white\n"
      "  --list-materials FILE  print the material names of scene FILE, one per line, and exit\n"
      "  --scale S            multiply every coordinate by S (1e-9..1e9; e.g. 0.001 for a scene\n"
      "                       in millimetres, to get metres); radiosity is per m^2 of the result\n"
      "  --cut-contacts on|off  cut large surfaces along the lines where walls stand on them\n"
      "                       with open space on both sides, so that no mesh element\n"
      "                       carries light through a wall (default on)\n"
      "\n"
      "Solver (thresholds are dimensionless: errors relative to the light each element\n"
      "receives, B relative to the scene's mean radiosity, areas relative to the total area,\n"
      "so they suit scenes in any unit and any brightness):\n"
      "  --bf-low X           accuracy: the largest error a link may bring its receiver,\n"
      "                       relative to the receiver's light; the main quality setting\n"
      "                       (> 0, default %g; smaller is more accurate and slower)\n"
      "  --bf-start X         first BF_e of the multigrid schedule (>= BF_low; default 0:\n"
      "                       equal to BF_low, one level; the paper's schedule: e.g. 0.05)\n"
      "  --bf-first X         BF_e of a clustered solve's first linking, before any light is\n"
      "                       gathered: the direct light's resolution (>= 0, may be below\n"
      "                       BF_low; default 0: a quarter of the first BF_e)\n"
      "  --bf-factor X        BF_e is divided by X per level (> 1, default %g)\n"
      "  --area-min X         minimum element area A_e, relative to the total area\n"
      "                       (0 <= X < 1, default 0: equal to BF_low)\n"
      "  --importance E       a polygon smaller than the finest mesh element (A_e / 4) may\n"
      "                       take errors (A_e / 4 / A)^E times larger: it weighs that much\n"
      "                       less in the picture (0 <= E <= 1, default %g; 0: all alike)\n"
      "  --b-eps X            convergence: max change of B below X (>= 0, default 0:\n"
      "                       equal to BF_low, at most B_max)\n"
      "  --b-max X            B_max of the relaxed inner loop (>= B_eps, default %g)\n"
      "  --no-relax           rigid inner loop (paper Figure 3) instead of section 2.2.4\n"
      "  --no-extrapolate     plain Jacobi iterations, without the Aitken extrapolation\n"
      "                       of the radiosity every 5 iterations without new links\n"
      "  --rays K             rays per link for the visible fraction H (1..4096, default %d)\n"
      "  --seed N             jitter seed (0..2^64-1, default %llu)\n"
      "  --threads N          worker threads (0..%d, default 0: all cores)\n"
      "  --max-iters N        stop after N iterations (1..%d, default %d)\n"
      "  --cluster MODE       hierarchical clustering: auto (default: on for scenes with\n"
      "                       more surface pairs than --max-pairs), on or off\n"
      "  --max-pairs N        surface pairs above which --cluster auto clusters and\n"
      "                       --cluster off refuses the scene (0: no limit, default %g)\n"
      "  -h, --help           this help\n"
      "  --version            print the version (hrad MAJOR.MINOR.PATCH) and exit\n"
      "\n"
      "Exit status: 0 done, 1 bad input or a failure (nothing written), 2 usage error;\n"
      "interrupted by a signal: 128+N (Ctrl-C: 130; a second Ctrl-C stops at once).\n",
      scenes, MIN_SIDE, MAX_SIDE, MAX_PIXELS, CKPT_EVERY, MIN_EMIT, MAX_EMIT, d.bf_low,
      d.bf_factor, d.importance, d.b_max, d.rays, (unsigned long long)d.seed, MAX_THREADS, INT_MAX,
      d.max_iters, d.max_links);
}

/* A real option value: a finite number and nothing else. */
static double parse_real(const char *opt, const char *v) {
  char *end;
  double x = strtod(v, &end);
  if (end == v || *end) die_usage("%s: not a number: '%s'", opt, v);
  if (!isfinite(x)) die_usage("%s: not a finite number: '%s'", opt, v);
  return x;
}

/* A whole-number option value in [lo, hi]: the range is checked on the double, before any cast
 * (so 1e300, inf and NaN are errors, not undefined behaviour). */
static double parse_whole(const char *opt, const char *v, double lo, double hi) {
  char *end;
  double x = strtod(v, &end);
  if (end == v || *end) die_usage("%s: not a number: '%s'", opt, v);
  if (!(x >= lo && x <= hi && x == floor(x)))
    die_usage("%s must be a whole number in %.0f..%.0f, got '%s'", opt, lo, hi, v);
  return x;
}

/* --seed: decimal digits only (all 2^64 seeds are reachable, none is rounded). */
static uint64_t parse_seed(const char *v) {
  char *end;
  errno = 0;
  unsigned long long x = strtoull(v, &end, 10);
  if (!*v || strspn(v, "0123456789") != strlen(v) || errno == ERANGE)
    die_usage("--seed must be a whole number in 0..%llu, got '%s'", (unsigned long long)UINT64_MAX,
              v);
  return (uint64_t)x;
}

/* 'n' comma-separated numbers at 's', followed by the end or ':'. */
static int parse_vec(const char *s, double *out, int n) {
  for (int i = 0; i < n; i++) {
    char *end;
    out[i] = strtod(s, &end);
    if (end == s) return 0;
    s = end;
    if (i + 1 < n) {
      if (*s != ',') return 0;
      s++;
    }
  }
  return *s == 0 || *s == ':';
}

static void parse_camera(cli *c, const char *v) {
  double e[3], a[3];
  const char *colon = strchr(v, ':');
  if (!colon || !parse_vec(v, e, 3) || !parse_vec(colon + 1, a, 3))
    die_usage("--camera: expected 'ex,ey,ez:ax,ay,az[:fov]', got '%s'", v);
  for (int k = 0; k < 3; k++)
    if (!isfinite(e[k]) || !isfinite(a[k]))
      die_usage("--camera: the coordinates must be finite numbers, got '%s'", v);
  double d[3] = {a[0] - e[0], a[1] - e[1], a[2] - e[2]};
  double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (!isfinite(len)) die_usage("--camera: coordinates too large in '%s'", v);
  if (!(len > 0)) die_usage("--camera: the eye and the look-at point coincide in '%s'", v);
  c->camera.eye = (hr_vec3){e[0], e[1], e[2]};
  c->camera.at = (hr_vec3){a[0], a[1], a[2]};
  c->camera.up = (hr_vec3){0, 1, 0};
  c->camera.fov_deg = 50;
  const char *c2 = strchr(colon + 1, ':');
  if (c2) {
    char *end;
    c->camera.fov_deg = strtod(c2 + 1, &end);
    if (end == c2 + 1 || *end) die_usage("--camera: fov is not a number in '%s'", v);
  }
  if (!(c->camera.fov_deg > 1 && c->camera.fov_deg < 179))
    die_usage("--camera: fov must be in (1, 179) degrees, got '%s'", v);
  c->have_camera = 1;
}

/* Luminous efficacy used to turn lumens into watts: 683 lm/W, the definition of the lumen at
 * 555 nm (a white source is less efficient per watt; see README, "Units"). */
#define LM_PER_W 683.0

/* The value of --emit NAME=VALUE in familiar units: "60W" (the radiant power of all polygons of
 * the material together) or "800lm" (their luminous flux, at 683 lm/W). Returns the unit (1 W,
 * 2 lm) and the power in watts in '*watts', or 0 when VALUE is R,G,B. */
static int parse_power(const char *val, double *watts) {
  const size_t n = strlen(val);
  int unit = 0;
  size_t k = n;
  if (n > 1 && val[n - 1] == 'W') unit = 1, k = n - 1;
  else if (n > 2 && !strcmp(val + n - 2, "lm")) unit = 2, k = n - 2;
  if (!unit) return 0;
  char num[64];
  if (k >= sizeof num) return -1;
  memcpy(num, val, k);
  num[k] = '\0';
  char *end;
  errno = 0;
  const double x = strtod(num, &end);
  if (end == num || *end || errno || !(x > 0) || !isfinite(x)) return -1;
  *watts = unit == 2 ? x / LM_PER_W : x;
  return unit;
}

static void parse_emit(cli *c, const char *v) {
  const char *eq = strrchr(v, '=');
  double rgb[3], watts = 0;
  const int unit = eq ? parse_power(eq + 1, &watts) : 0;
  if (unit < 0 || (unit > 0 && !(watts >= MIN_EMIT && watts <= MAX_EMIT)))
    die_usage("--emit: a power must be a number > 0 followed by W or lm (at most %g W), got "
              "'%s'", MAX_EMIT, v);
  if (unit > 0) rgb[0] = rgb[1] = rgb[2] = -watts; /* negative: a power, spread in apply_emit */
  else if (!eq || eq == v || !parse_vec(eq + 1, rgb, 3) || strchr(eq + 1, ':'))
    die_usage("--emit: expected NAME=R,G,B, NAME=POWERW or NAME=FLUXlm, got '%s'", v);
  for (int k = 0; k < 3 && unit == 0; k++)
    if (rgb[k] != 0 && !(rgb[k] >= MIN_EMIT && rgb[k] <= MAX_EMIT))
      die_usage("--emit: radiosity must be 0 or in [%g, %g], got '%s'", MIN_EMIT, MAX_EMIT, v);
  if (c->nemit == c->cap_emit) {
    c->cap_emit = c->cap_emit ? 2 * c->cap_emit : 8;
    c->emit_name = realloc(c->emit_name, (size_t)c->cap_emit * sizeof *c->emit_name);
    c->emit_rgb = realloc(c->emit_rgb, (size_t)c->cap_emit * sizeof *c->emit_rgb);
    if (!c->emit_name || !c->emit_rgb) die_usage("out of memory");
  }
  c->emit_name[c->nemit] = strndup(v, (size_t)(eq - v));
  if (!c->emit_name[c->nemit]) die_usage("out of memory");
  memcpy(c->emit_rgb[c->nemit], rgb, sizeof rgb);
  c->nemit++;
}

/* --outputs LIST: comma-separated names of OUT_NAMES; anything else is a usage error. */
static void parse_outputs(cli *c, const char *v) {
  c->outputs = 0;
  for (const char *p = v;;) {
    size_t n = strcspn(p, ",");
    int k = 0;
    while (OUT_NAMES[k] && !(strlen(OUT_NAMES[k]) == n && !strncmp(OUT_NAMES[k], p, n))) k++;
    if (!OUT_NAMES[k])
      die_usage("--outputs: unknown output '%.*s' in '%s' (choose from csv, json, png, ply, glb, "
                "viewer)",
                (int)n, p, v);
    c->outputs |= 1u << k;
    if (!p[n]) break;
    p += n + 1;
  }
}

/* One side of --size: the decimal digits between 'a' and 'b' (-1 if there are none or anything
 * else; LONG_MAX if too many). */
static long parse_side(const char *a, const char *b) {
  if (b <= a) return -1;
  for (const char *p = a; p < b; p++)
    if (*p < '0' || *p > '9') return -1;
  if (b - a > 9) return LONG_MAX;
  long x = 0;
  for (const char *p = a; p < b; p++) x = 10 * x + (*p - '0');
  return x;
}

static void parse_size(cli *c, const char *v) {
  const char *x = strchr(v, 'x');
  long w = x ? parse_side(v, x) : -1, h = x ? parse_side(x + 1, x + 1 + strlen(x + 1)) : -1;
  if (w < 0 || h < 0) die_usage("--size: expected WxH (e.g. 800x600), got '%s'", v);
  if (w < MIN_SIDE || h < MIN_SIDE || w > MAX_SIDE || h > MAX_SIDE)
    die_usage("--size: each side must be in %d..%d, got '%s'", MIN_SIDE, MAX_SIDE, v);
  if (w * h > MAX_PIXELS)
    die_usage("--size: at most %ld pixels (e.g. 8192x8192), got '%s'", MAX_PIXELS, v);
  c->w = (int)w;
  c->h = (int)h;
}

/* --checkpoint FILE must be creatable (its directory exists and is writable, FILE is not a
 * directory); --resume FILE must be a readable file. */
static void check_ckpt_paths(const cli *c) {
  struct stat st;
  if (c->resume) {
    if (stat(c->resume, &st) != 0) die_usage("--resume %s: %s", c->resume, strerror(errno));
    if (!S_ISREG(st.st_mode)) die_usage("--resume %s: not a file", c->resume);
    if (access(c->resume, R_OK) != 0) die_usage("--resume %s: %s", c->resume, strerror(errno));
  }
  if (c->ckpt) {
    if (stat(c->ckpt, &st) == 0 && S_ISDIR(st.st_mode))
      die_usage("--checkpoint %s: is a directory", c->ckpt);
    char dir[PATH_MAX];
    const char *slash = strrchr(c->ckpt, '/');
    if (!slash)
      strcpy(dir, ".");
    else if (slash == c->ckpt)
      strcpy(dir, "/");
    else
      snprintf(dir, sizeof dir, "%.*s", (int)(slash - c->ckpt), c->ckpt);
    if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode))
      die_usage("--checkpoint %s: no directory %s", c->ckpt, dir);
    if (access(dir, W_OK) != 0)
      die_usage("--checkpoint %s: cannot write in %s: %s", c->ckpt, dir, strerror(errno));
  }
}

static void parse_args(cli *c, int argc, char **argv) {
  hr_options_default(&c->opt);
  hr_options *o = &c->opt;
  c->outdir = "hrad-out";
  c->w = 800;
  c->h = 600;
  c->ckpt_every = CKPT_EVERY;
  /* annealing: within 5% of the best Z of any method at 2-64 ranks, and as fast as random
   * owners on 2 ranks of one machine (BENCHMARKS.md, "Graph balancing, sixth pass") */
  c->balance_random = 0, c->balance_seed = 1;
  c->balance_method = HR_BALANCE_ANNEAL, c->balance_alpha = 0.5, c->balance_idle = 0.1;
  c->outputs = OUT_CSV | OUT_JSON | OUT_PNG | OUT_PLY | OUT_GLB | OUT_VIEWER;
  c->scale = 1;
  c->cut_contacts = 1;
  int opts_done = 0;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
#define NEXT() (i + 1 < argc ? argv[++i] : (die_usage("%s needs a value", a), ""))
    if (opts_done || a[0] != '-' || a[1] == 0) {
      if (c->scene_arg) die_usage("more than one scene given ('%s' and '%s')", c->scene_arg, a);
      if (!*a) die_usage("empty scene name");
      c->scene_arg = a;
    } else if (!strcmp(a, "--")) {
      opts_done = 1;
    } else if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage();
      exit(0);
    } else if (!strcmp(a, "--version")) {
      printf("hrad %s\n", hr_version());
      exit(0);
    } else if (!strcmp(a, "-o") || !strcmp(a, "--out")) {
      c->outdir = NEXT();
      if (!*c->outdir) die_usage("%s: empty directory name", a);
    } else if (!strcmp(a, "--quiet")) c->quiet = 1;
    else if (!strcmp(a, "--no-progress")) c->no_progress = 1;
    else if (!strcmp(a, "--snapshots")) c->snapshots = 1;
    else if (!strcmp(a, "--hdr")) c->hdr = 1;
    else if (!strcmp(a, "--no-relax")) o->relax = 0;
    else if (!strcmp(a, "--no-extrapolate")) o->extrapolate = 0;
    else if (!strcmp(a, "--bf-low")) {
      const char *v = NEXT();
      if (!((o->bf_low = parse_real(a, v)) > 0)) die_usage("--bf-low must be > 0, got '%s'", v);
    } else if (!strcmp(a, "--bf-start")) {
      const char *v = NEXT();
      if (!((o->bf_start = parse_real(a, v)) >= 0))
        die_usage("--bf-start must be >= 0, got '%s'", v);
    } else if (!strcmp(a, "--importance")) {
      const char *v = NEXT();
      o->importance = parse_real(a, v);
      if (!(o->importance >= 0 && o->importance <= 1))
        die_usage("--importance must be in [0, 1], got '%s'", v);
    } else if (!strcmp(a, "--bf-first")) {
      const char *v = NEXT();
      if (!((o->bf_first = parse_real(a, v)) >= 0))
        die_usage("--bf-first must be >= 0, got '%s'", v);
    } else if (!strcmp(a, "--bf-factor")) {
      const char *v = NEXT();
      if (!((o->bf_factor = parse_real(a, v)) > 1))
        die_usage("--bf-factor must be > 1, got '%s'", v);
    } else if (!strcmp(a, "--area-min")) {
      const char *v = NEXT();
      o->area_min = parse_real(a, v);
      if (!(o->area_min >= 0 && o->area_min < 1))
        die_usage("--area-min must be in [0, 1) (0: BF_low), got '%s'", v);
    } else if (!strcmp(a, "--b-eps")) {
      const char *v = NEXT();
      if (!((o->b_eps = parse_real(a, v)) >= 0))
        die_usage("--b-eps must be >= 0 (0: BF_low), got '%s'", v);
    } else if (!strcmp(a, "--b-max")) {
      const char *v = NEXT();
      if (!((o->b_max = parse_real(a, v)) > 0)) die_usage("--b-max must be > 0, got '%s'", v);
    } else if (!strcmp(a, "--cluster")) {
      const char *v = NEXT();
      if (!strcmp(v, "auto")) o->cluster = HR_CLUSTER_AUTO;
      else if (!strcmp(v, "on")) o->cluster = HR_CLUSTER_ON;
      else if (!strcmp(v, "off")) o->cluster = HR_CLUSTER_OFF;
      else die_usage("--cluster must be auto, on or off, got '%s'", v);
    } else if (!strcmp(a, "--cut-contacts")) {
      const char *v = NEXT();
      if (!strcmp(v, "on")) c->cut_contacts = 1;
      else if (!strcmp(v, "off")) c->cut_contacts = 0;
      else die_usage("--cut-contacts must be on or off, got '%s'", v);
    } else if (!strcmp(a, "--max-pairs")) {
      const char *v = NEXT();
      if (!((o->max_links = parse_real(a, v)) >= 0))
        die_usage("--max-pairs must be >= 0 (0: no limit), got '%s'", v);
    } else if (!strcmp(a, "--exposure")) {
      const char *v = NEXT();
      if (!((c->exposure = parse_real(a, v)) > 0)) die_usage("--exposure must be > 0, got '%s'", v);
    } else if (!strcmp(a, "--rays")) o->rays = (int)parse_whole(a, NEXT(), 1, 4096);
    else if (!strcmp(a, "--seed")) o->seed = parse_seed(NEXT());
    else if (!strcmp(a, "--threads")) o->threads = (int)parse_whole(a, NEXT(), 0, MAX_THREADS);
    else if (!strcmp(a, "--max-iters")) o->max_iters = (int)parse_whole(a, NEXT(), 1, INT_MAX);
    else if (!strcmp(a, "--verify"))
      c->verify_paths = (int64_t)parse_whole(a, NEXT(), 1, MAX_VERIFY);
    else if (!strcmp(a, "--verify-image"))
      c->verify_spp = (int)parse_whole(a, NEXT(), 1, MAX_VERIFY_SPP);
    else if (!strcmp(a, "--checkpoint")) {
      c->ckpt = NEXT();
      if (!*c->ckpt) die_usage("--checkpoint: empty file name");
    } else if (!strcmp(a, "--checkpoint-every")) {
      const char *v = NEXT();
      if (!((c->ckpt_every = parse_real(a, v)) >= 0))
        die_usage("--checkpoint-every must be >= 0 seconds, got '%s'", v);
    } else if (!strcmp(a, "--resume")) {
      c->resume = NEXT();
      if (!*c->resume) die_usage("--resume: empty file name");
    } else if (!strcmp(a, "--balance")) {
      const char *v = NEXT();
      static const char *const graph[] = {"none", "anneal", "metis", "orb"};
      c->balance_method = HR_BALANCE_NONE;
      if (!strcmp(v, "area")) c->balance_random = 0;
      else if (!strcmp(v, "random")) c->balance_random = 1, c->balance_seed = 1;
      else if (!strncmp(v, "random:", 7))
        c->balance_random = 1, c->balance_seed = parse_seed(v + 7);
      else {
        int k = 0;
        while (k < 4 && strcmp(v, graph[k])) k++;
        if (k == 4)
          die_usage("--balance must be 'random', 'random:SEED', 'area', 'none', 'anneal', "
                    "'metis' or 'orb', got '%s'", v);
        /* the graph methods start from compact pieces of the scene, then move subtrees */
        c->balance_random = 0, c->balance_method = k;
      }
    } else if (!strcmp(a, "--balance-alpha")) {
      const char *v = NEXT();
      c->balance_alpha = parse_real(a, v);
      if (!(c->balance_alpha >= 0 && c->balance_alpha <= 1))
        die_usage("--balance-alpha must be in [0, 1], got '%s'", v);
    } else if (!strcmp(a, "--balance-idle")) {
      const char *v = NEXT();
      c->balance_idle = parse_real(a, v);
      if (!(c->balance_idle >= 0 && c->balance_idle <= 1))
        die_usage("--balance-idle must be in [0, 1], got '%s'", v);
    } else if (!strcmp(a, "--dump-graph")) {
      c->dump_graph = NEXT();
      if (!*c->dump_graph) die_usage("--dump-graph: empty file name");
    } else if (!strcmp(a, "--outputs")) {
      parse_outputs(c, NEXT());
    } else if (!strcmp(a, "--scale")) {
      const char *v = NEXT();
      c->scale = parse_real(a, v);
      if (!(c->scale >= 1e-9 && c->scale <= 1e9))
        die_usage("--scale must be in [1e-9, 1e9], got '%s'", v);
    } else if (!strcmp(a, "--list-materials")) {
      c->list_mats = NEXT();
      if (!*c->list_mats) die_usage("--list-materials: empty file name");
    } else if (!strcmp(a, "--camera")) parse_camera(c, NEXT());
    else if (!strcmp(a, "--emit")) parse_emit(c, NEXT());
    else if (!strcmp(a, "--size")) parse_size(c, NEXT());
    else die_usage("unknown option '%s'", a);
#undef NEXT
  }
  if (!c->scene_arg) c->scene_arg = "room";
  check_ckpt_paths(c);
  /* the checks of hr_solver_create that relate two options, with its messages */
  if (!(o->bf_start == 0 || o->bf_start >= o->bf_low))
    die_usage("--bf-start must be 0 (BF_low) or >= --bf-low (%g < %g)", o->bf_start, o->bf_low);
  if (!(o->b_max >= o->b_eps))
    die_usage("--b-max must be >= --b-eps (%g < %g)", o->b_max, o->b_eps);
  /* the images must fit in memory: the renderer's 2x2 samples (depth, colour, leaf index: 80
   * bytes a pixel), the float image and the PNG rows; --verify-image adds two float images */
  double need = (double)c->w * c->h * (95.0 + (c->verify_spp ? 24.0 : 0.0));
  long pages = sysconf(_SC_PHYS_PAGES), psize = sysconf(_SC_PAGESIZE);
  double mem = pages > 0 && psize > 0 ? (double)pages * (double)psize : 0;
  if (mem > 0 && need > 0.8 * mem)
    die_usage("--size %dx%d: the images need about %.1f GB, more than this machine's %.1f GB of "
              "memory allows",
              c->w, c->h, need / 1e9, mem / 1e9);
}

/* ---------------------------------------------------------------- the output directory */

/* Checks -o before any work (every problem is a usage error), cleans up what killed runs left,
 * and creates this run's staging directory beside DIR. */
static void prepare_outdir(cli *c) {
  const char *o = c->outdir;
  size_t n = strlen(o);
  if (n >= sizeof c->disp) die_usage("-o: directory name too long");
  memcpy(c->disp, o, n + 1);
  while (n > 1 && c->disp[n - 1] == '/') c->disp[--n] = 0;
  struct stat st, ps;
  int exists = stat(c->disp, &st) == 0;
  if (exists) {
    if (!S_ISDIR(st.st_mode)) die_usage("-o %s: exists and is not a directory", o);
    if (!realpath(c->disp, c->dir)) die_usage("-o %s: %s", o, strerror(errno));
  } else {
    if (errno != ENOENT) die_usage("-o %s: %s", o, strerror(errno));
    if (lstat(c->disp, &st) == 0) die_usage("-o %s: a symbolic link to nothing", o);
    char par[PATH_MAX], rp[PATH_MAX];
    const char *slash = strrchr(c->disp, '/');
    const char *base = slash ? slash + 1 : c->disp;
    if (!slash)
      strcpy(par, ".");
    else if (slash == c->disp)
      strcpy(par, "/");
    else
      snprintf(par, sizeof par, "%.*s", (int)(slash - c->disp), c->disp);
    if (!realpath(par, rp)) die_usage("-o %s: %s: %s", o, par, strerror(errno));
    if (stat(rp, &ps) != 0 || !S_ISDIR(ps.st_mode))
      die_usage("-o %s: %s is not a directory", o, par);
    if (strlen(rp) + strlen(base) + 2 > sizeof c->dir) die_usage("-o %s: path too long", o);
    join(c->dir, sizeof c->dir, strcmp(rp, "/") ? rp : "", base);
  }
  if (!strcmp(c->dir, "/"))
    die_usage("-o %s: hrad replaces its output directory as a whole; give one of its own", o);
  char *ls = strrchr(c->dir, '/');
  const char *base = ls + 1;
  if (ls == c->dir)
    strcpy(c->parent, "/");
  else
    snprintf(c->parent, sizeof c->parent, "%.*s", (int)(ls - c->dir), c->dir);
  if (exists) {
    if (stat(c->parent, &ps) != 0 || ps.st_dev != st.st_dev)
      die_usage("-o %s: a mount point; hrad replaces its output directory as a whole, so give "
                "a directory inside it",
                o);
    char cwd[PATH_MAX];
    size_t dl = strlen(c->dir);
    if (getcwd(cwd, sizeof cwd) && !strncmp(cwd, c->dir, dl) && (cwd[dl] == 0 || cwd[dl] == '/'))
      die_usage("-o %s: holds the working directory; hrad replaces its output directory as a "
                "whole, so give one of its own",
                o);
    DIR *d = opendir(c->dir);
    if (!d) die_usage("-o %s: cannot read: %s", o, strerror(errno));
    struct dirent *e;
    while ((e = readdir(d))) {
      struct stat es;
      if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
      if (fstatat(dirfd(d), e->d_name, &es, AT_SYMLINK_NOFOLLOW) == 0 && !S_ISREG(es.st_mode) &&
          !S_ISLNK(es.st_mode)) {
        char nm[256];
        snprintf(nm, sizeof nm, "%s", e->d_name);
        closedir(d);
        die_usage("-o %s: holds '%s', which is not a file; hrad replaces its output directory "
                  "as a whole, so give one of its own",
                  o, nm);
      }
    }
    closedir(d);
    if (c->snapshots && access(c->dir, W_OK) != 0)
      die_usage("-o %s: not writable (--snapshots): %s", o, strerror(errno));
  }
  clean_stale(c, base);
  snprintf(c->stage, sizeof c->stage, "%s/.%.200s.hrad-%ld", c->parent, base, (long)getpid());
  lock();
  if (mkdir(c->stage, 0777) != 0) {
    int e = errno;
    c->stage[0] = 0;
    die_usage("-o %s: cannot write in %s: %s", o, c->parent, strerror(e));
  }
  c->stage_fd = open(c->stage, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  char mk[sizeof c->stage + 32];
  join(mk, sizeof mk, c->stage, MARKER);
  int fd = c->stage_fd >= 0 && flock(c->stage_fd, LOCK_EX | LOCK_NB) == 0
               ? open(mk, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666)
               : -1;
  if (fd < 0) {
    int e = errno;
    remove_stage(c);
    die_usage("-o %s: cannot write in %s: %s", o, c->parent, strerror(e));
  }
  close(fd);
  unlock();
}

/* Before the exchange: hard-links every file of DIR that is not an output of the previous set
 * ('old') nor replaced by one of the new set into the staging directory, so that it stays in
 * DIR throughout. */
static void carry_over(cli *c, const names *old) {
  DIR *d = opendir(c->dir);
  if (!d) fail("%s: cannot read: %s", c->disp, strerror(errno));
  struct dirent *e;
  while ((e = readdir(d))) {
    const char *n = e->d_name;
    if (!strcmp(n, ".") || !strcmp(n, "..") || !strcmp(n, MANIFEST) || !strcmp(n, MARKER) ||
        !strncmp(n, SNAP_TMP, strlen(SNAP_TMP)) || names_has(old, n) || names_has(&c->outs, n))
      continue;
    struct stat st;
    if (fstatat(dirfd(d), n, &st, AT_SYMLINK_NOFOLLOW) != 0) continue; /* gone meanwhile */
    char nm[256];
    snprintf(nm, sizeof nm, "%s", n);
    if (!S_ISREG(st.st_mode) && !S_ISLNK(st.st_mode)) {
      closedir(d);
      fail("%s: holds '%s', which is not a file; nothing written (hrad replaces its output "
           "directory as a whole)",
           c->disp, nm);
    }
    if (linkat(dirfd(d), n, c->stage_fd, n, 0) != 0) {
      int er = errno;
      closedir(d);
      fail("%s/%s: cannot keep this file through the exchange (hard link: %s); nothing written",
           c->disp, nm, strerror(er));
    }
  }
  closedir(d);
}

/* Removes what carry_over linked into the staging directory. */
static void drop_carried(cli *c) {
  DIR *d = opendir(c->stage);
  if (!d) return;
  struct dirent *e;
  while ((e = readdir(d)))
    if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..") && strcmp(e->d_name, MANIFEST) &&
        strcmp(e->d_name, MARKER) && !names_has(&c->outs, e->d_name))
      unlinkat(dirfd(d), e->d_name, 0);
  closedir(d);
}

/* The list of the new set, DIR/.hrad-outputs. */
static void write_manifest(cli *c) {
  char path[sizeof c->stage + 32];
  join(path, sizeof path, c->stage, MANIFEST);
  FILE *f = fopen(path, "w");
  if (!f) fail("%s: cannot write: %s", path, strerror(errno));
  fprintf(f, "# hrad: the files of the output set in this directory. The next hrad run into it\n"
             "# replaces them as a set; other files are kept.\n");
  for (int i = 0; i < c->outs.n; i++) {
    if (c->outs.v[i][0] == '#') fputc('\\', f); /* not a comment */
    for (const char *p = c->outs.v[i]; *p; p++) {
      if (*p == '\\' || *p == '\n') fputc('\\', f);
      fputc(*p == '\n' ? 'n' : *p, f);
    }
    fputc('\n', f);
  }
  int ok = fflush(f) == 0 && !ferror(f), e = ok ? 0 : errno;
  if (fclose(f) != 0 && ok) ok = 0, e = errno;
  if (!ok) fail("%s: write failed: %s", path, strerror(e ? e : EIO));
}

/* Without renameat2 (some network file systems): the files of the set are renamed into DIR one
 * by one and the previous set's other files removed; not atomic as a set. */
static void commit_by_file(cli *c, const names *old) {
  fprintf(stderr,
          "hrad: warning: %s: this file system cannot exchange directories; the outputs are "
          "replaced one by one\n",
          c->disp);
  char from[sizeof c->stage + 300], to[PATH_MAX + 300];
  for (int i = 0; i <= c->outs.n; i++) {
    const char *n = i < c->outs.n ? c->outs.v[i] : MANIFEST;
    join(from, sizeof from, c->stage, n);
    join(to, sizeof to, c->dir, n);
    if (rename(from, to) != 0)
      fail("%s/%s: cannot move into place: %s", c->disp, n, strerror(errno));
  }
  for (int i = 0; i < old->n; i++)
    if (!names_has(&c->outs, old->v[i])) {
      join(to, sizeof to, c->dir, old->v[i]);
      unlink(to);
    }
  rm_flat(c->stage);
}

/* Makes the staging directory DIR: see the file comment. */
static void commit(cli *c) {
  lock();
  write_manifest(c);
  char mk[sizeof c->stage + 32];
  join(mk, sizeof mk, c->stage, MARKER);
  for (int attempt = 0;; attempt++) {
    if (attempt == 8) fail("%s: kept changing while the outputs were committed; nothing written",
                           c->disp);
    struct stat st;
    if (lstat(c->dir, &st) != 0) {
      if (errno != ENOENT) fail("%s: %s", c->disp, strerror(errno));
      unlink(mk);
      if (renameat2(AT_FDCWD, c->stage, AT_FDCWD, c->dir, RENAME_NOREPLACE) == 0) break;
      int e = errno;
      if (e == EINVAL || e == ENOSYS) { /* no flags here: rename replaces only an empty DIR */
        if (rename(c->stage, c->dir) == 0) break;
        e = errno;
      }
      if (e == EEXIST || e == ENOTEMPTY) continue; /* DIR appeared meanwhile */
      fail("%s: cannot move the outputs into place: %s", c->disp, strerror(e));
    }
    if (!S_ISDIR(st.st_mode)) fail("%s: no longer a directory; nothing written", c->disp);
    names old = {0};
    read_manifest(c->dir, &old);
    carry_over(c, &old);
    chmod(c->stage, st.st_mode & 07777);
    unlink(mk);
    if (renameat2(AT_FDCWD, c->stage, AT_FDCWD, c->dir, RENAME_EXCHANGE) == 0) {
      /* the staging name now holds the previous DIR */
      if (!tidy_old(c->stage, c->dir, &old, &c->outs))
        fprintf(stderr,
                "hrad: warning: %s: the previous contents of %s, left there because they hold "
                "files that hrad did not write\n",
                c->stage, c->disp);
      names_free(&old);
      break;
    }
    int e = errno;
    if (e == ENOENT) { /* DIR went away meanwhile */
      drop_carried(c);
      names_free(&old);
      continue;
    }
    if (e == EINVAL || e == ENOSYS || e == EXDEV) {
      commit_by_file(c, &old);
      names_free(&old);
      break;
    }
    fail("%s: cannot exchange it with the new outputs: %s", c->disp, strerror(e));
  }
  c->stage[0] = 0;
  if (c->stage_fd >= 0) close(c->stage_fd);
  c->stage_fd = -1;
  unlock();
}

/* ---------------------------------------------------------------- output files */

static const char *render_error(hr_status st) {
  return st == HR_ERR_NOMEM     ? "rendering failed: out of memory"
         : st == HR_ERR_TOO_BIG ? "rendering failed: image too large"
                                : "rendering failed";
}

static void render(const cli *c, const hr_mesh *m, const hr_leaf *leaves, int64_t n, int mode,
                   double clamp, float *img) {
  hr_status st = hr_render_ex(c->scene, m, leaves, n, &c->cam, c->w, c->h, mode, 2, clamp, img);
  if (st != HR_OK) fail("%s", render_error(st));
}

/* The current solution's leaves ('*leaves', '*n'; caller frees) and smooth mesh (returned;
 * caller destroys), and the exposure of the PNGs: --exposure, else automatic. Exits on error. */
static hr_mesh *solution_mesh(const cli *c, const hr_solver *s, hr_leaf **leaves, int64_t *n,
                              double *expo) {
  if (hr_solver_leaves(s, leaves, n) != HR_OK) fail("out of memory");
  hr_mesh *m;
  hr_status st = hr_mesh_build(c->scene, *leaves, *n, &m);
  if (st != HR_OK) fail("building the mesh failed%s", st == HR_ERR_NOMEM ? ": out of memory" : "");
  *expo = c->exposure > 0 ? c->exposure : hr_exposure_auto(m);
  return m;
}

/* A solution with an infinite or NaN radiosity is never written (a wrong answer must not come
 * with exit status 0). */
static void check_finite(const cli *c, const hr_solver *s) {
  hr_leaf *l;
  int64_t n;
  if (hr_solver_leaves(s, &l, &n) != HR_OK) fail("out of memory");
  for (int64_t i = 0; i < n; i++)
    for (int k = 0; k < 3; k++)
      if (!isfinite(l[i].B[k])) {
        double b = l[i].B[k];
        int surf = l[i].surf;
        free(l);
        fail("%s: the solution is not finite (radiosity %g on surface %d); nothing written",
             c->scene->name, b, surf);
      }
  free(l);
}

/* Reflectance at or above this in any channel gets a warning (check_white). */
#define RHO_WARN 0.99

/* A warning naming the materials in use that reflect RHO_WARN or more of the light in some
 * channel: no real surface does (white paint reflects about 0.85), but exports that keep the
 * colour in a texture often write `Kd 1 1 1` everywhere. The solve stays bounded (a closed box
 * of rho 1 has no steady state; the solver stops at its convergence test), but the result is
 * far too bright and slow to converge. */
static void check_white(const cli *c) {
  const hr_scene *sc = c->scene;
  if (c->quiet) return;
  char *used = calloc((size_t)sc->nmats, 1);
  if (!used) return;
  for (int i = 0; i < sc->nsurfs; i++) { /* a textured polygon's variant counts for its base */
    const hr_material *mt = &sc->mats[sc->surfs[i].material];
    if (fmax(mt->rho[0], fmax(mt->rho[1], mt->rho[2])) >= RHO_WARN) used[mt->base] = 1;
  }
  char names[200] = "";
  int n = 0;
  for (int m = 0; m < sc->nmats; m++) {
    if (!used[m]) continue;
    if (n++ < 4)
      snprintf(names + strlen(names), sizeof names - strlen(names), "%s'%.40s'", n > 1 ? ", " : "",
               sc->mats[m].name);
  }
  free(used);
  if (n > 4) snprintf(names + strlen(names), sizeof names - strlen(names), " and %d more", n - 4);
  if (n)
    fprintf(stderr,
            "hrad: warning: %s: %d material%s reflect%s %g%% or more of the light (%s); no real "
            "surface does, and exports whose colour lives in a texture often write Kd 1 1 1: "
            "expect a too bright result and slow convergence\n",
            sc->name, n, n > 1 ? "s" : "", n > 1 ? "" : "s", RHO_WARN * 100, names);
}

/* A warning when no light reaches any surface that does not emit: the usual cause is polygons
 * wound the wrong way (surfaces are one-sided, lit from the side they face). */
static void check_lit(const cli *c, const hr_solver *s) {
  const hr_scene *sc = c->scene;
  int others = 0;
  for (int i = 0; i < sc->nsurfs; i++) {
    const int p = sc->surfs[i].poly, m = sc->surfs[i].material;
    if ((i > 0 && sc->surfs[i - 1].poly == p) ||
        sc->mats[m].emit[0] + sc->mats[m].emit[1] + sc->mats[m].emit[2] > 0)
      continue; /* a polygon's surfaces are consecutive */
    others++;
    double b[3];
    hr_solver_poly_radiosity(s, p, b);
    if (b[0] + b[1] + b[2] > 0) return;
  }
  if (others > 0 && !c->quiet)
    fprintf(stderr,
            "hrad: warning: %s: no light reaches any of the %d polygons that do not emit; "
            "surfaces are one-sided, lit on the side from which their vertices run "
            "counter-clockwise: are the polygons (or the lamps) wound the other way?\n",
            sc->name, others);
}

/* Writes the mesh files --outputs asks for: SCENE.ply, SCENE.glb, viewer.html (the viewer
 * embeds a .glb: without glb in --outputs one is written under a hidden name and removed). */
static void write_meshes(cli *c, const hr_mesh *m, double expo) {
  hr_err err = {{0}};
  char path[sizeof c->stage + 300], name[PATH_MAX];
  const char *nm = c->scene->name;
  lock();
  if (c->outputs & OUT_PLY) {
    snprintf(name, sizeof name, "%s.ply", nm);
    check(hr_ply_write(stage_file(c, name, path, sizeof path), m, expo, &err), &err);
  }
  int viewer = c->viewer && (c->outputs & OUT_VIEWER);
  if (c->outputs & OUT_GLB) {
    snprintf(name, sizeof name, "%s.glb", nm);
    check(hr_glb_write(stage_file(c, name, path, sizeof path), m, expo, &err), &err);
  } else if (viewer) {
    snprintf(name, sizeof name, ".hrad-viewer.glb");
    if (!*join(path, sizeof path, c->stage, name)) fail("%s/%s: path too long", c->disp, name);
    check(hr_glb_write(path, m, expo, &err), &err);
  }
  if (viewer)
    check(hr_viewer_write(stage_file(c, "viewer.html", path, sizeof path), name, &err), &err);
  if (viewer && !(c->outputs & OUT_GLB) && join(path, sizeof path, c->stage, name)[0])
    unlink(path);
  unlock();
}

/* Renders the current solution from the run's camera and writes 'png_name' into the staging
 * directory (unless 'all' and --outputs leaves out png). With 'all' it also writes the elements
 * image, the PFM and the mesh files that --outputs asks for. */
static void write_pictures(cli *c, const hr_solver *s, const char *png_name, int all) {
  hr_err err = {{0}};
  unsigned meshes = c->outputs & (OUT_PLY | OUT_GLB | OUT_VIEWER);
  int png = !all || (c->outputs & OUT_PNG);
  if (!png && !meshes && !c->hdr) return;
  hr_leaf *leaves;
  int64_t n;
  double expo;
  hr_mesh *m = solution_mesh(c, s, &leaves, &n, &expo);
  float *img = malloc((size_t)c->w * c->h * 3 * sizeof *img);
  if (!img) fail("out of memory");
  char path[sizeof c->stage + 300], name[PATH_MAX];
  const char *nm = c->scene->name;
  if (png) {
    render(c, m, leaves, n, 0, 1.0 / expo, img);
    lock();
    check(hr_png_write(stage_file(c, png_name, path, sizeof path), c->w, c->h, img, expo, &err),
          &err);
    unlock();
  }
  if (all && c->hdr) {
    check_stop(c);
    render(c, m, leaves, n, 0, 0, img);
    snprintf(name, sizeof name, "%s.pfm", nm);
    lock();
    check(hr_pfm_write(stage_file(c, name, path, sizeof path), c->w, c->h, img, &err), &err);
    unlock();
  }
  if (all && png) {
    check_stop(c);
    render(c, m, leaves, n, 1, 1.0 / expo, img);
    snprintf(name, sizeof name, "%s-elements.png", nm);
    lock();
    check(hr_png_write(stage_file(c, name, path, sizeof path), c->w, c->h, img, expo, &err), &err);
    unlock();
  }
  if (all && meshes) {
    check_stop(c);
    write_meshes(c, m, expo);
  }
  free(img);
  hr_mesh_destroy(&m);
  free(leaves);
}

/* --snapshots: iter-NN.png joins the set and is hard-linked into DIR at once, to be watched. */
static void snapshot(cli *c, const hr_solver *s, int iter) {
  char name[64], from[sizeof c->stage + 64], tmp[PATH_MAX + 64], to[PATH_MAX + 64];
  snprintf(name, sizeof name, "iter-%02d.png", iter);
  write_pictures(c, s, name, 0);
  c->nsnap++;
  lock();
  if (mkdir(c->dir, 0777) != 0 && errno != EEXIST)
    fail("%s: cannot create directory: %s", c->disp, strerror(errno));
  join(from, sizeof from, c->stage, name);
  snprintf(tmp, sizeof tmp, "%s/%s%ld", c->dir, SNAP_TMP, (long)getpid());
  join(to, sizeof to, c->dir, name);
  unlink(tmp);
  if (link(from, tmp) != 0 || rename(tmp, to) != 0) {
    int e = errno;
    unlink(tmp);
    fail("%s/%s: cannot write the snapshot: %s", c->disp, name, strerror(e));
  }
  unlock();
}
/* ---------------------------------------------------------------- --verify, --verify-image */

static double norm3(const double v[3]) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

/* One polygon of the comparison between hrad and the path tracer. */
typedef struct vrow {
  double hrad[3], ref[3], se[3];
  double rel;  /* |hrad - ref| / |ref| over the RGB vector; NaN when the reference is 0 */
  int mat;     /* material of the polygon's first surface */
  int emitter; /* some surface of the polygon emits */
} vrow;

/* |a - ref| / |ref| (RGB norms), NaN when ref is 0. */
static double rel_err(const double a[3], const double ref[3]) {
  double d[3] = {a[0] - ref[0], a[1] - ref[1], a[2] - ref[2]}, r = norm3(ref);
  return r > 0 ? norm3(d) / r : NAN;
}

/* Fills the material and emitter flag of every polygon from its surfaces. */
static void poly_materials(const hr_scene *sc, vrow *rows) {
  for (int p = 0; p < sc->npolys; p++) rows[p].mat = -1, rows[p].emitter = 0;
  for (int i = 0; i < sc->nsurfs; i++) {
    const hr_surface *f = &sc->surfs[i];
    const double *e = sc->mats[f->material].emit;
    if (rows[f->poly].mat < 0) rows[f->poly].mat = f->material;
    rows[f->poly].emitter |= e[0] > 0 || e[1] > 0 || e[2] > 0;
  }
}

static const char *mat_name(const hr_scene *sc, int m) {
  return m >= 0 && sc->mats[m].name ? sc->mats[m].name : "-";
}

/* Writes 's' as one CSV field, quoted when it holds a comma, quote or line break. */
static void csv_field(FILE *f, const char *s) {
  if (!strpbrk(s, ",\"\r\n")) {
    fputs(s, f);
    return;
  }
  fputc('"', f);
  for (; *s; s++) {
    if (*s == '"') fputc('"', f);
    fputc(*s, f);
  }
  fputc('"', f);
}

/* verify.csv in the staging directory: one row per polygon (rel_err is nan where the reference
 * is 0). */
static void write_verify_csv(cli *c, const vrow *rows) {
  char path[sizeof c->stage + 32];
  lock();
  stage_file(c, "verify.csv", path, sizeof path);
  FILE *f = fopen(path, "w");
  if (!f) fail("%s: cannot write: %s", path, strerror(errno));
  fprintf(f, "id,area,material,emitter,hrad_r,hrad_g,hrad_b,ref_r,ref_g,ref_b,se_r,se_g,se_b,"
             "rel_err\n");
  for (int p = 0; p < c->scene->npolys; p++) {
    const vrow *r = &rows[p];
    fprintf(f, "%d,%.9g,", hr_scene_poly_input(c->scene, p), c->scene->poly_area[p]);
    csv_field(f, mat_name(c->scene, r->mat));
    fprintf(f, ",%d,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g\n", r->emitter, r->hrad[0],
            r->hrad[1], r->hrad[2], r->ref[0], r->ref[1], r->ref[2], r->se[0], r->se[1], r->se[2],
            r->rel);
  }
  int ok = fflush(f) == 0 && !ferror(f), e = ok ? 0 : errno;
  if (fclose(f) != 0 && ok) ok = 0, e = errno;
  if (!ok) fail("%s: write failed: %s", path, strerror(e ? e : EIO));
  unlock();
}

/* The per-polygon table (to c->rep, see there): hrad's radiosity, the reference with its 95%
 * confidence interval (1.96 standard errors) per channel, and the relative error. */
static void print_verify_table(const cli *c, const hr_scene *sc, const vrow *rows,
                               int64_t paths) {
  fprintf(c->rep, "verify: %lld paths per polygon\n", (long long)paths);
  fprintf(c->rep, "verify:   id material           area       hrad r, g, b                 "
                  "reference r, g, b (+- 95%%)                  rel.err\n");
  for (int p = 0; p < sc->npolys; p++) {
    const vrow *r = &rows[p];
    fprintf(c->rep, "verify: %4d %-16.16s %9.4g  %8.4g %8.4g %8.4g  ", hr_scene_poly_input(sc, p),
            mat_name(sc, r->mat),
            sc->poly_area[p], r->hrad[0], r->hrad[1], r->hrad[2]);
    for (int k = 0; k < 3; k++) fprintf(c->rep, " %8.4g+-%-7.2g", r->ref[k], 1.96 * r->se[k]);
    if (isnan(r->rel))
      fprintf(c->rep, "       -");
    else
      fprintf(c->rep, " %7.2f%%", 100 * r->rel);
    fprintf(c->rep, "%s\n", r->emitter ? " emitter" : "");
  }
}

/* The summary line: area-weighted RMS of the relative error over non-emitting polygons with a
 * non-zero reference, the worst of them, and the reference's own noise (area-weighted RMS of
 * |se| / |ref|). */
static void print_verify_summary(const cli *c, const hr_scene *sc, const vrow *rows,
                                 double secs, int64_t paths) {
  double sa = 0, se2 = 0, sn2 = 0, worst = -1;
  int cnt = 0, wp = -1;
  for (int p = 0; p < sc->npolys; p++) {
    const vrow *r = &rows[p];
    double A = sc->poly_area[p], nr = norm3(r->ref);
    if (r->emitter || !(nr > 0)) continue;
    sa += A;
    se2 += A * r->rel * r->rel;
    sn2 += A * (norm3(r->se) / nr) * (norm3(r->se) / nr);
    cnt++;
    if (r->rel > worst) worst = r->rel, wp = p;
  }
  double rate = secs > 0 ? (double)paths * sc->npolys / secs : 0;
  if (cnt == 0 || !(sa > 0)) {
    fprintf(c->rep, "verify: no lit non-emitting polygon to compare; path tracer %.1f s\n", secs);
    return;
  }
  fprintf(c->rep,
          "verify: area-weighted RMS error %.2f%% over %d non-emitting polygons, worst %.2f%% "
          "(polygon %d, %s); reference noise %.2f%%; path tracer %.1f s (%.3g paths/s)\n",
          100 * sqrt(se2 / sa), cnt, 100 * worst, hr_scene_poly_input(sc, wp),
          mat_name(sc, rows[wp].mat),
          100 * sqrt(sn2 / sa), secs, rate);
}

/* --verify: traces every polygon with c->verify_paths paths, compares with the solution 's',
 * prints the table (unless --quiet) and the summary, and writes verify.csv. */
static void verify_polys(cli *c, const hr_solver *s) {
  const hr_scene *sc = c->scene;
  hr_err err = {{0}};
  vrow *rows = calloc((size_t)sc->npolys, sizeof *rows);
  double (*mean)[3] = malloc((size_t)sc->npolys * sizeof *mean);
  double (*se)[3] = malloc((size_t)sc->npolys * sizeof *se);
  if (!rows || !mean || !se) fail("out of memory");
  hr_pt_options o = {c->verify_paths, c->opt.seed, c->opt.threads};
  double t0 = now_s();
  check(hr_pt_polys(sc, &o, mean, se, &err), &err);
  double secs = now_s() - t0;
  poly_materials(sc, rows);
  for (int p = 0; p < sc->npolys; p++) {
    hr_solver_poly_radiosity(s, p, rows[p].hrad);
    memcpy(rows[p].ref, mean[p], sizeof rows[p].ref);
    memcpy(rows[p].se, se[p], sizeof rows[p].se);
    rows[p].rel = rel_err(rows[p].hrad, rows[p].ref);
  }
  write_verify_csv(c, rows);
  if (!c->quiet) print_verify_table(c, sc, rows, c->verify_paths);
  print_verify_summary(c, sc, rows, secs, c->verify_paths);
  free(rows);
  free(mean);
  free(se);
}

static double normf3(const float *v) {
  return sqrt((double)v[0] * v[0] + (double)v[1] * v[1] + (double)v[2] * v[2]);
}

/* The mean relative per-pixel error |img - ref| / |ref| (RGB norms) over the pixels whose
 * reference exceeds 1% of the image's mean |ref|, with the mean relative noise of the reference
 * over the same pixels, as one line (to c->rep). */
static void print_image_error(const cli *c, const float *img, const float *ref, const float *se,
                              double secs) {
  size_t np = (size_t)c->w * c->h, cnt = 0;
  double mean = 0, err = 0, noise = 0;
  for (size_t i = 0; i < np; i++) mean += normf3(ref + 3 * i) / np;
  for (size_t i = 0; i < np; i++) {
    double r = normf3(ref + 3 * i);
    if (!(r > 0.01 * mean)) continue;
    float d[3] = {img[3 * i] - ref[3 * i], img[3 * i + 1] - ref[3 * i + 1],
                  img[3 * i + 2] - ref[3 * i + 2]};
    err += normf3(d) / r;
    noise += normf3(se + 3 * i) / r;
    cnt++;
  }
  if (cnt == 0) {
    fprintf(c->rep, "verify-image: the reference image is black; path tracer %.1f s\n", secs);
    return;
  }
  fprintf(c->rep,
          "verify-image: mean relative per-pixel error %.2f%% over %zu of %zu pixels (reference "
          "above 1%% of its mean); reference noise %.2f%%; %dx%d at %d spp, path tracer %.1f s\n",
          100 * err / cnt, cnt, np, 100 * noise / cnt, c->w, c->h, c->verify_spp, secs);
}

/* --verify-image: path-traces the run's view at c->verify_spp samples per pixel, writes
 * SCENE-reference.png (the exposure of SCENE.png), and compares hrad's smooth
 * rendering (linear, unclamped) with it. */
static void verify_image(cli *c, const hr_solver *s) {
  hr_err err = {{0}};
  hr_leaf *leaves;
  int64_t n;
  double expo;
  hr_mesh *m = solution_mesh(c, s, &leaves, &n, &expo);
  size_t np = (size_t)c->w * c->h;
  float *img = malloc(3 * np * sizeof *img), *ref = malloc(3 * np * sizeof *ref);
  float *se = malloc(3 * np * sizeof *se);
  if (!img || !ref || !se) fail("out of memory");
  render(c, m, leaves, n, 0, -1, img);
  hr_pt_options o = {1, c->opt.seed, c->opt.threads};
  double t0 = now_s();
  check(hr_pt_image(c->scene, &c->cam, c->w, c->h, c->verify_spp, &o, ref, se, &err), &err);
  double secs = now_s() - t0;
  check_stop(c);
  char name[PATH_MAX], path[sizeof c->stage + PATH_MAX];
  snprintf(name, sizeof name, "%s-reference.png", c->scene->name);
  lock();
  check(hr_png_write(stage_file(c, name, path, sizeof path), c->w, c->h, ref, expo, &err), &err);
  unlock();
  print_image_error(c, img, ref, se, secs);
  free(img);
  free(ref);
  free(se);
  hr_mesh_destroy(&m);
  free(leaves);
}


/* ---------------------------------------------------------------- the run */

/* Writes the checkpoint (state after iteration 'iter'); a failure is a warning, the run goes
 * on. */
/* Writes the checkpoint: with MPI, every rank calls it (rank 0 writes the file). A failure is a
 * warning; the run goes on, and does not try again at the end. */
static void save_ckpt(cli *c, const hr_solver *s, int iter) {
  hr_err err = {{0}};
  c->ckpt_last = now_s();
  c->ckpt_iter = iter; /* the same on every rank, written or not */
  c->ckpt_ok = hr_solver_checkpoint(s, c->ckpt, &err) == HR_OK;
  if (!c->ckpt_ok && g_rank == 0) say("hrad: warning: checkpoint not written: %s", err.msg);
}

static int on_iter(void *ud, const hr_solver *s, const hr_iter_info *it) {
  cli *c = ud;
  if (!c->quiet)
    say("iter %3d  BF_e %.3e  elements %9lld  links %10lld  max change %.3e  %8.3f s",
            it->iter, it->bf_e, (long long)it->elements, (long long)it->links, it->max_change,
            it->elapsed_s);
  /* with MPI, every rank decides alike: a signal seen by any rank, rank 0's clock */
  const int stop = hr_dist_any(g_dist, atomic_load(&g_stop) != 0);
  if (stop) {
    if (c->ckpt) {
      save_ckpt(c, s, it->iter);
      if (c->ckpt_ok && g_rank == 0)
        say("hrad: saved iteration %d to %s; continue with --resume %s", it->iter, c->ckpt,
            c->ckpt);
    }
    return 1;
  }
  if (c->ckpt &&
      hr_dist_any(g_dist, g_rank == 0 && now_s() - c->ckpt_last >= c->ckpt_every))
    save_ckpt(c, s, it->iter);
  if (c->snap_collect) { /* distributed: every rank sends its leaves to rank 0 first */
    hr_err cerr = {{0}};
    if (hr_solver_collect((hr_solver *)s, &cerr) != HR_OK) fail("%s", cerr.msg);
  }
  if (c->snapshots) snapshot(c, s, it->iter);
  return hr_dist_any(g_dist, atomic_load(&g_stop) != 0);
}

/* A built-in name, or one with a parameter ("hall:8"; the library checks the parameter) that
 * cannot be a scene file: no '/', no scene file extension, no such file. */
static int is_builtin(const char *name) {
  for (const char *const *n = hr_scene_builtin_names(); *n; n++) {
    size_t k = strlen(*n);
    struct stat sb;
    if (strncmp(*n, name, k) != 0) continue;
    if (name[k] == '\0') return 1;
    const char *dot = strrchr(name, '.');
    if (name[k] == ':' && !strchr(name, '/') && !(dot && hr_scene_format_known(name)) &&
        stat(name, &sb) != 0)
      return 1;
  }
  return 0;
}

/* ", N clusters' links moved" for a clustered run whose balancing gave clusters new ranks. */
static const char *cluster_moves_note(int64_t moves) {
  static char b[64];
  b[0] = 0;
  if (moves > 0) snprintf(b, sizeof b, ", %lld clusters' links moved", (long long)moves);
  return b;
}

/* The per-rank table of a distributed run (PETSc -log_view style): each rank, then min, mean
 * and max over ranks; imbalance is max over mean of the busy time. */
static void print_ranks(const hr_rank_stats *r, int n) {
  fprintf(stderr, "rank surfaces     links    leaves        rays   busy s    mpi s  mpi calls"
                  "   MB sent   RSS MB\n");
  double lo[8], hi[8], sum[8];
  for (int i = 0; i < n; i++) {
    const double v[8] = {(double)r[i].surfaces, (double)r[i].links,     (double)r[i].leaves,
                         (double)r[i].rays,     r[i].busy_s,            r[i].mpi_s,
                         (double)r[i].mpi_calls, (double)r[i].mpi_bytes / 1e6};
    for (int k = 0; k < 8; k++) {
      lo[k] = i ? fmin(lo[k], v[k]) : v[k];
      hi[k] = i ? fmax(hi[k], v[k]) : v[k];
      sum[k] = (i ? sum[k] : 0) + v[k];
    }
    fprintf(stderr, "%4d %8d %9lld %9lld %11lld %8.3f %8.3f %10lld %9.2f %8.1f\n", r[i].rank,
            r[i].surfaces, (long long)r[i].links, (long long)r[i].leaves, (long long)r[i].rays,
            r[i].busy_s, r[i].mpi_s, (long long)r[i].mpi_calls, (double)r[i].mpi_bytes / 1e6,
            r[i].peak_rss_mb);
  }
  const char *name[3] = {" min", "mean", " max"};
  for (int j = 0; j < 3; j++) {
    double v[8];
    for (int k = 0; k < 8; k++) v[k] = j == 0 ? lo[k] : j == 1 ? sum[k] / n : hi[k];
    fprintf(stderr, "%s %8.0f %9.0f %9.0f %11.0f %8.3f %8.3f %10.0f %9.2f\n", name[j], v[0],
            v[1], v[2], v[3], v[4], v[5], v[6], v[7]);
  }
  fprintf(stderr, "imbalance (max/mean busy) %.2f, links max/mean %.2f\n",
          sum[4] > 0 ? hi[4] / (sum[4] / n) : 1, sum[1] > 0 ? hi[1] / (sum[1] / n) : 1);
  /* memory of the graph (paper 2.2: each rank holds its share) and point-to-point traffic */
  fprintf(stderr, "rank  elements    ghosts  elem MB  link MB   messages   msg MB\n");
  /* the whole graph is every rank's own elements and links: a rank's share against 1/P of it */
  double mem_max = 0, graph = 0;
  for (int i = 0; i < n; i++) {
    fprintf(stderr, "%4d %9lld %9lld %8.2f %8.2f %10lld %8.2f\n", r[i].rank,
            (long long)r[i].elements, (long long)r[i].ghosts, r[i].elem_mb, r[i].link_mb,
            (long long)r[i].msgs, (double)r[i].msg_bytes / 1e6);
    const double local = (double)(r[i].elements + r[i].ghosts);
    mem_max = fmax(mem_max, r[i].elem_mb + r[i].link_mb);
    graph += r[i].link_mb + (local > 0 ? r[i].elem_mb * (double)r[i].elements / local : 0);
  }
  fprintf(stderr, "element+link memory: max %.2f MB a rank, %.2f x 1/P of the graph (%.2f MB)\n",
          mem_max, graph > 0 ? mem_max / (graph / n) : 1, graph);
  if (r[0].balancings > 0)
    fprintf(stderr, "graph balancing: %lld times, %lld of them moved elements%s\n",
            (long long)r[0].balancings, (long long)r[0].migrations,
            cluster_moves_note(r[0].cluster_moves));
  /* per phase: busy and MPI (idle included) seconds, min/mean/max over the ranks */
  static const char *const ph[4] = {"init graph", "refine", "gather", "push-pull"};
  fprintf(stderr, "phase         busy min   mean    max    mpi min   mean    max\n");
  for (int k = 0; k < 4; k++) {
    double b[3] = {INFINITY, 0, -INFINITY}, m[3] = {INFINITY, 0, -INFINITY};
    for (int i = 0; i < n; i++) {
      b[0] = fmin(b[0], r[i].phase_busy[k]), b[1] += r[i].phase_busy[k] / n;
      b[2] = fmax(b[2], r[i].phase_busy[k]);
      m[0] = fmin(m[0], r[i].phase_mpi[k]), m[1] += r[i].phase_mpi[k] / n;
      m[2] = fmax(m[2], r[i].phase_mpi[k]);
    }
    fprintf(stderr, "%-12s %8.3f %6.3f %6.3f   %8.3f %6.3f %6.3f\n", ph[k], b[0], b[1], b[2], m[0],
            m[1], m[2]);
  }
}

/* "hrad: wrote DIR/{a,b,...}" and the number of snapshots. */
/* Loads 'arg' (a built-in name or a scene file) with --scale applied. Exits on error. */
static hr_scene *load_scene(const cli *c, const char *arg, const hr_log *log) {
  hr_err err = {{0}};
  hr_scene *scene = NULL;
  hr_status st;
  if (is_builtin(arg)) {
    st = hr_scene_builtin(arg, &scene, &err);
  } else {
    struct stat sb;
    const char *dot = strrchr(arg, '.');
    int file_like = strchr(arg, '/') || (dot && dot > arg && hr_scene_format_known(arg));
    if (stat(arg, &sb) != 0 && !file_like) {
      char list[256];
      scene_list(list, sizeof list);
      fail("unknown scene '%s' (built-in: %s; or a path to a scene file)", arg, list);
    }
    st = hr_scene_load(arg, log, &scene, &err);
  }
  check(st, &err);
  if (c->scale != 1 && hr_scene_scale(scene, c->scale) != HR_OK) {
    hr_scene_destroy(&scene);
    fail("%s: --scale %g puts coordinates beyond %g", arg, c->scale, HR_COORD_MAX);
  }
  return scene;
}

/* The names of the scene's input materials, comma-separated, in 'out' (cut with "..."). */
static void material_list(const hr_scene *sc, char *out, size_t n) {
  out[0] = '\0';
  for (int k = 0; k < hr_scene_material_count(sc); k++) {
    size_t l = strlen(out);
    const char *nm = sc->mats[hr_scene_material_at(sc, k)].name;
    if (l + strlen(nm) + 8 >= n) {
      snprintf(out + l, n - l, ", ...");
      return;
    }
    snprintf(out + l, n - l, "%s'%s'", k ? ", " : "", nm);
  }
}

/* --emit NAME=POWER: the radiant exitance that gives the material's polygons together that
 * power (W over their area, white), in place of the negative power parse_emit left. */
static void emit_power(cli *c, const hr_scene *scene, int i) {
  const double watts = -c->emit_rgb[i][0];
  double area = 0;
  for (int k = 0; k < scene->nsurfs; k++)
    if (!strcmp(scene->mats[scene->surfs[k].material].name, c->emit_name[i]))
      area += scene->surfs[k].area;
  const double m = area > 0 ? watts / area : 0;
  if (!(area > 0) || !(m >= MIN_EMIT && m <= MAX_EMIT))
    fail("--emit: %s: %g W over %g m^2 of material '%s' is not a radiosity in [%g, %g] W/m^2",
         scene->name, watts, area, c->emit_name[i], MIN_EMIT, MAX_EMIT);
  for (int k = 0; k < 3; k++) c->emit_rgb[i][k] = m;
  if (!c->quiet)
    fprintf(stderr, "hrad: --emit %s: %g W over %g m^2: radiosity %g W/m^2\n", c->emit_name[i],
            watts, area, m);
}

/* --emit: each name must be a material of the scene; an unknown one lists those that exist. */
static void apply_emit(cli *c, hr_scene *scene) {
  hr_err err = {{0}};
  for (int i = 0; i < c->nemit; i++) {
    if (hr_scene_find_material(scene, c->emit_name[i]) < 0) {
      char list[400];
      material_list(scene, list, sizeof list);
      fail("--emit: %s has no material named '%s'; its materials: %s", scene->name,
           c->emit_name[i], list);
    }
    if (c->emit_rgb[i][0] < 0) emit_power(c, scene, i);
    check(hr_scene_set_emit(scene, c->emit_name[i], c->emit_rgb[i], &err), &err);
    free(c->emit_name[i]);
  }
}

/* --list-materials FILE: the input materials' names, one per line, on stdout. */
static void list_materials(const cli *c) {
  hr_log log = {c->quiet ? NULL : warn_cb, NULL};
  hr_scene *scene = load_scene(c, c->list_mats, &log);
  warn_summary();
  for (int k = 0; k < hr_scene_material_count(scene); k++)
    printf("%s\n", scene->mats[hr_scene_material_at(scene, k)].name);
  hr_scene_destroy(&scene);
  exit(fflush(stdout) == 0 ? 0 : 1);
}

static void print_wrote(const cli *c) {
  fprintf(stderr, "hrad: wrote %s/{", c->disp);
  int k = 0;
  for (int i = 0; i < c->outs.n; i++)
    if (strncmp(c->outs.v[i], "iter-", 5)) fprintf(stderr, "%s%s", k++ ? "," : "", c->outs.v[i]);
  fprintf(stderr, "}");
  if (c->nsnap) fprintf(stderr, " and %d snapshots iter-NN.png", c->nsnap);
  fprintf(stderr, "\n");
}

int main(int argc, char **argv) {
  static cli c;
  c.stage_fd = -1;
  g_cli = &c;
  pthread_mutexattr_t ma;
  pthread_mutexattr_init(&ma);
  pthread_mutexattr_settype(&ma, PTHREAD_MUTEX_RECURSIVE);
  pthread_mutex_init(&g_lock, &ma);
  {
    hr_err derr = {{0}};
    if (hr_dist_start(&argc, &argv, &g_dist, &derr) != HR_OK) {
      fprintf(stderr, "hrad: %s\n", derr.msg);
      return 1;
    }
    g_rank = hr_dist_rank(g_dist);
    g_ranks = hr_dist_size(g_dist);
  }
  parse_args(&c, argc, argv);
  c.snap_collect = c.snapshots && hr_dist_size(g_dist) > 1;
  if (c.list_mats) list_materials(&c);
#ifdef _OPENMP
  /* --threads bounds the whole process, the renderer included: a process-wide setting is the
   * tool's to make, not the library's (the solver's loops take their count from num_threads
   * clauses and leave the process's setting alone). */
  if (c.opt.threads > 0) omp_set_num_threads(c.opt.threads);
#endif
  if (g_rank != 0) c.quiet = 1, c.snapshots = 0; /* rank 0 prints and writes */
  start_signals();
  if (g_rank == 0) {
    g_together = 0;
    prepare_outdir(&c);
    g_together = 1;
  }
  c.viewer = g_rank == 0 && hr_viewer_available();
  if (!c.viewer && g_rank == 0)
    fprintf(stderr,
            "hrad: warning: %s: three.js not found, so no viewer.html (set HRAD_THREE_DIR to a "
            "node_modules/three directory%s)\n",
            hr_viewer_three_dir() ? hr_viewer_three_dir() : "built-in copy",
            hr_viewer_three_dir() ? ", or unset it" : ", or rebuild after scripts/setup.sh");
  hr_err err = {{0}};
  hr_log log = {c.quiet ? NULL : warn_cb, NULL};
  hr_scene *scene = load_scene(&c, c.scene_arg, &log);
  warn_summary();
  hr_status st;
  check_stop(&c);
  apply_emit(&c, scene);
  free(c.emit_name);
  free(c.emit_rgb);
  if (c.cut_contacts) {
    double ae = (c.opt.area_min > 0 ? c.opt.area_min : c.opt.bf_low) * hr_scene_total_area(scene);
    if (hr_scene_cut_contacts(scene, sqrt(ae), &c.cuts) != HR_OK) fail("out of memory");
  }
  c.scene = scene;
  check_white(&c);
  if (c.have_camera) c.cam = c.camera;
  else if (scene->has_camera) c.cam = scene->camera;
  else hr_scene_auto_camera(scene, &c.cam);
  hr_solver *s = NULL;
  check(hr_solver_create(scene, &c.opt, &s, &err), &err);
  if (hr_dist_size(g_dist) > 1) { /* --balance random:N scatters elements (N = 0 acts as 1) */
    const uint64_t scatter = c.balance_random ? (c.balance_seed ? c.balance_seed : 1) : 0;
    check(hr_solver_set_dist(s, g_dist, NULL, scatter, &err), &err);
    check(hr_solver_set_balance(s, c.balance_method, c.balance_alpha, c.balance_idle, &err),
          &err);
  }
  if (c.resume) {
    check(hr_solver_resume(s, c.resume, &err), &err);
    if (!c.quiet) {
      hr_stats rs;
      hr_solver_stats(s, &rs);
      fprintf(stderr, "hrad: resumed from %s after iteration %d%s\n", c.resume, rs.iterations,
              rs.converged ? " (already converged)" : "");
    }
  }
  if (!c.quiet) {
    hr_vec3 lo, hi;
    hr_scene_bounds(scene, &lo, &hi);
    fprintf(stderr,
            "hrad: scene '%s': %d polygons, %d surfaces, %d materials, area %.4g, bounds "
            "(%.6g %.6g %.6g)-(%.6g %.6g %.6g)\n",
            scene->name, scene->npolys, scene->nsurfs, scene->nmats, hr_scene_total_area(scene),
            lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
    if (c.cuts.surfaces > 0)
      fprintf(stderr, "hrad: cut %d surface%s along %d contact line%s into %d\n",
              c.cuts.surfaces, c.cuts.surfaces == 1 ? "" : "s", c.cuts.lines,
              c.cuts.lines == 1 ? "" : "s", c.cuts.pieces);
  }
  c.ckpt_last = now_s();
  progress_start(s, !c.quiet && !c.no_progress);
  st = hr_solver_run(s, on_iter, &c, &err);
  hr_solver_set_progress(s, NULL, NULL);
  progress_stop();
  const int nranks = hr_dist_size(g_dist);
  if (nranks > 1 && st == HR_OK) st = hr_solver_collect(s, &err); /* the leaves to rank 0 */
  if (st == HR_OK && c.dump_graph) st = hr_solver_dump_graph(s, c.dump_graph, &err);
  hr_rank_stats *ranks = NULL;
  if (nranks > 1 && st == HR_OK) { /* every rank's share, to rank 0 */
    if (g_rank == 0) ranks = xrealloc(NULL, (size_t)nranks * sizeof *ranks);
    hr_err rerr = {{0}};
    if (hr_solver_rank_stats(s, ranks, &rerr) != HR_OK) {
      free(ranks);
      ranks = NULL;
    }
  }
  if (st == HR_OK && c.ckpt) { /* the final state (every rank takes part) */
    hr_stats es;
    hr_solver_stats(s, &es);
    if (c.ckpt_iter != es.iterations) save_ckpt(&c, s, es.iterations);
  }
  if (g_rank != 0) { /* its part is done: rank 0 writes the outputs */
    if (st != HR_OK) check(st, &err);
    hr_solver_destroy(&s);
    hr_scene_destroy(&scene);
    leave(atomic_load(&g_stop) ? 128 + atomic_load(&g_stop) : 0);
  }
  g_together = 0;
  check_stop(&c);
  check(st, &err);
  check_finite(&c, s);
  check_lit(&c, s);
  char path[sizeof c.stage + 300], name[PATH_MAX];
  c.rep = open_memstream(&c.rep_buf, &c.rep_len);
  if (!c.rep) c.rep = stderr;
  progress_writing();
  lock();
  if (c.outputs & OUT_CSV)
    check(hr_report_csv(stage_file(&c, "surfaces.csv", path, sizeof path), s, &err), &err);
  if (c.outputs & OUT_JSON)
    check(hr_report_json(stage_file(&c, "stats.json", path, sizeof path), s, &c.opt, &err), &err);
  unlock();
  check_stop(&c);
  snprintf(name, sizeof name, "%s.png", scene->name);
  write_pictures(&c, s, name, 1);
  progress_stop();
  check_stop(&c);
  if (c.verify_paths) verify_polys(&c, s);
  check_stop(&c);
  if (c.verify_spp) verify_image(&c, s);
  check_stop(&c);
  commit(&c);
  if (c.rep != stderr && fclose(c.rep) == 0 && c.rep_buf) fputs(c.rep_buf, stderr);
  free(c.rep_buf);
  hr_stats stats;
  hr_solver_stats(s, &stats);
  if (!c.quiet) {
    hr_report_table(stderr, &stats);
    if (ranks) print_ranks(ranks, nranks);
    if (!stats.converged)
      fprintf(stderr, "hrad: warning: stopped after %d iterations without converging\n",
              stats.iterations);
    print_wrote(&c);
  }
  free(ranks);
  names_free(&c.outs);
  hr_solver_destroy(&s);
  hr_scene_destroy(&scene);
  g_together = 1;
  leave(0);
}
