/* progress.c: the progress callback of a solver (hrad.h, hr_solver_set_progress).
 *
 * The solver's structure (solver_impl.h) has no field for it yet, so the callbacks live in a
 * small table keyed by the solver's address, guarded by a mutex; a solver that has none costs
 * a lookup per report. When struct hr_solver gains a 'progress' field this file shrinks to the
 * setter and the report function. */
#include "hrad.h"

#include <pthread.h>
#include <stdlib.h>

typedef struct entry {
  const hr_solver *s;
  hr_progress_fn fn;
  void *ud;
} entry;

static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static entry *g_tab;
static int g_n, g_cap;

/* Index of 's' in the table, or -1. Call with the lock held. */
static int find(const hr_solver *s) {
  for (int i = 0; i < g_n; i++)
    if (g_tab[i].s == s) return i;
  return -1;
}

hr_status hr_solver_set_progress(hr_solver *s, hr_progress_fn fn, void *ud) {
  if (!s) return HR_ERR_INVALID;
  hr_status st = HR_OK;
  pthread_mutex_lock(&g_lock);
  int i = find(s);
  if (!fn) {
    if (i >= 0) g_tab[i] = g_tab[--g_n];
  } else if (i >= 0) {
    g_tab[i].fn = fn, g_tab[i].ud = ud;
  } else if (g_n == g_cap) {
    int cap = g_cap ? 2 * g_cap : 4;
    entry *t = realloc(g_tab, (size_t)cap * sizeof *t);
    if (t) {
      g_tab = t, g_cap = cap;
      g_tab[g_n++] = (entry){s, fn, ud};
    } else {
      st = HR_ERR_NOMEM;
    }
  } else {
    g_tab[g_n++] = (entry){s, fn, ud};
  }
  pthread_mutex_unlock(&g_lock);
  return st;
}

void hr_solver_progress_report(const hr_solver *s, hr_phase phase, double fraction) {
  pthread_mutex_lock(&g_lock);
  int i = find(s);
  entry e = i >= 0 ? g_tab[i] : (entry){0};
  pthread_mutex_unlock(&g_lock);
  if (!e.fn) return;
  /* the callback runs outside the lock: it may set another solver's callback */
  fraction = fraction > 0 ? (fraction < 1 ? fraction : 1) : 0; /* NaN -> 0 */
  e.fn(e.ud, phase, fraction);
}
