/* checkpoint.c: saving the solver's state at an iteration boundary and resuming from it.
 *
 * The file names elements and links by their global ids (gids) and lists them in a canonical
 * order (elements by gid, links by receiver gid and then source gid), so it does not depend on
 * where anything sits in memory: not on the thread count, and later not on how elements are
 * spread over processes. Element geometry is not stored (it follows from the gid); the per-element
 * state the next iteration reads is (B, what it sends, the oracle's reference and spread, the
 * open fraction, the extrapolation's samples). Because the solver's sums run in gid order
 * (hr_link_sort, gather), a resumed run ends bit-identical to an uninterrupted one.
 *
 * Layout (little-endian): "HRADCKP1", u32 version, u64 scene hash, u64 options hash, the progress
 * of Figure 3 (with the extrapolation window), the elements, the links with their candidate
 * lists, and a u64 checksum of all that precedes it. A file is written to PATH.tmp and renamed
 * into place, so a kill leaves the previous checkpoint intact. */
#include "cluster.h"
#include "mpi/dist.h"
#include "solver_impl.h"
#include "vec.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAGIC "HRADCKP1"
#define VERSION 10u

/* ---------------------------------------------------------------- hashing */

static uint64_t hash_bytes(uint64_t h, const void *p, size_t n) {
  const unsigned char *b = p;
  for (size_t i = 0; i < n; i += 8) {
    uint64_t w = 0;
    memcpy(&w, b + i, n - i < 8 ? n - i : 8);
    h = u64_mix(h ^ w) + i;
  }
  return u64_mix(h ^ n);
}

/* Everything of the scene the solution depends on. */
static uint64_t scene_hash(const hr_scene *sc) {
  uint64_t h = hash_bytes(0x5ce11e, &sc->nsurfs, sizeof sc->nsurfs);
  for (int i = 0; i < sc->nsurfs; i++) {
    const hr_surface *f = &sc->surfs[i];
    h = hash_bytes(h, &f->nverts, sizeof f->nverts);
    h = hash_bytes(h, f->v, sizeof f->v[0] * (size_t)f->nverts);
    h = hash_bytes(h, &f->material, sizeof f->material);
    h = hash_bytes(h, &f->cut, sizeof f->cut);
  }
  for (int m = 0; m < sc->nmats; m++) {
    h = hash_bytes(h, sc->mats[m].rho, sizeof sc->mats[m].rho);
    h = hash_bytes(h, sc->mats[m].emit, sizeof sc->mats[m].emit);
  }
  return h;
}

/* The options the solution depends on (not threads or max_iters; max_links and cluster only
 * through whether the solver clusters). */
static uint64_t options_hash(const hr_options *o, int nsurfs) {
  const double d[] = {o->bf_low, o->bf_start, o->bf_factor, o->area_min, o->b_eps, o->b_max,
                      o->bf_first, o->importance};
  const int64_t n[] = {o->relax, o->relax_links, o->rays, (int64_t)o->seed, o->extrapolate,
                       hr_cluster_wanted(o, nsurfs)};
  return hash_bytes(hash_bytes(0x0b7, d, sizeof d), n, sizeof n);
}

/* ---------------------------------------------------------------- writing */

typedef struct writer {
  FILE *f;
  uint64_t h;
  int bad;
} writer;

static void put(writer *w, const void *p, size_t n) {
  if (w->bad) return;
  w->h = hash_bytes(w->h, p, n);
  if (fwrite(p, 1, n, w->f) != n) w->bad = 1;
}

/* The progress of Figure 3. */
typedef struct progress {
  int32_t iterations, converged, done, stopped, lazy, xwin, xlast, pad;
  double bf_e, unit, prev_change, stall_abs;
  int64_t stall, rays, initial_links;
  hr_timing t;
} progress;

/* Per element, after its gid. */
typedef struct elem_rec {
  double B[3], Bs[3], bref, bvar, open;
  double hist[2][3]; /* the extrapolation window's samples */
} elem_rec;

/* Per link, before its candidate ids. */
typedef struct link_rec {
  uint64_t r, s;
  float F, Fu, dF, dS, w[4];
  int32_t ncand;
} link_rec;

static int cmp_link_key(const void *a, const void *b) {
  const uint64_t *x = a, *y = b;
  if (x[0] != y[0]) return x[0] < y[0] ? -1 : 1;
  return x[1] < y[1] ? -1 : x[1] > y[1];
}

/* This rank's live links as the file stores them (a link_rec, then ncand int32 candidates),
 * into a fresh buffer of '*bytes' bytes; 0 when out of memory. */
static int pack_links(const hr_solver *s, char **out, int64_t *bytes) {
  int64_t nb = 0;
  for (int64_t k = 0; k < s->nlinks; k++)
    if (s->links[k].Fu >= 0)
      nb += (int64_t)sizeof(link_rec) +
            4 * (int64_t)(s->links[k].ncand > 0 ? s->links[k].ncand : 0);
  char *b = malloc((size_t)(nb > 0 ? nb : 1));
  if (!b) return 0;
  int64_t o = 0;
  for (int64_t k = 0; k < s->nlinks; k++) {
    const hr_link *l = &s->links[k];
    if (l->Fu < 0) continue;
    link_rec r;
    memset(&r, 0, sizeof r); /* no stray padding bytes in the file or its checksum */
    r.r = s->el[l->r].gid, r.s = s->el[l->s].gid;
    r.F = l->F, r.Fu = l->Fu, r.dF = l->dF, r.dS = l->dS, r.ncand = l->ncand;
    memcpy(r.w, l->w, sizeof r.w);
    memcpy(b + o, &r, sizeof r);
    o += (int64_t)sizeof r;
    if (l->ncand > 0) {
      memcpy(b + o, s->pool + l->cand_off, (size_t)l->ncand * sizeof(int32_t));
      o += 4 * (int64_t)l->ncand;
    }
  }
  *out = b;
  *bytes = nb;
  return 1;
}

/* In a distributed run, every rank's packed links to rank 0 (the others keep nothing). A
 * collective; the same status on every rank. */
static hr_status gather_links(const hr_solver *s, char **buf, int64_t *bytes, hr_err *err) {
  int64_t *sb = calloc((size_t)s->nranks, sizeof *sb);
  hr_status st = sb ? HR_OK : hr_err_set(err, HR_ERR_NOMEM, "out of memory");
  if ((st = hr_dist_agree(s, st, err)) == HR_OK) {
    sb[0] = *bytes;
    void *all = NULL;
    int64_t tot = 0;
    st = hr_dist_alltoall(s->dist, *buf, sb, &all, &tot);
    if (st == HR_OK) {
      free(*buf);
      *buf = all;
      *bytes = tot;
    } else {
      hr_err_set(err, st, "out of memory writing a checkpoint");
    }
  }
  free(sb);
  return st;
}

/* A stored element: its gid and state. */
typedef struct gid_rec {
  uint64_t gid;
  elem_rec r;
} gid_rec;

static int cmp_gid_rec(const void *a, const void *b) {
  const gid_rec *x = a, *y = b;
  return x->gid < y->gid ? -1 : x->gid > y->gid;
}

/* This rank's own elements as the file stores them; 0 when out of memory. */
static int pack_elements(const hr_solver *s, char **out, int64_t *bytes) {
  int64_t n = 0;
  for (int64_t e = 0; e < s->nel; e++) n += hr_owns(s, e);
  gid_rec *g = malloc((size_t)(n > 0 ? n : 1) * sizeof *g);
  if (!g) return 0;
  n = 0;
  for (int64_t e = 0; e < s->nel; e++) {
    if (!hr_owns(s, e)) continue;
    gid_rec *r = &g[n++];
    memset(r, 0, sizeof *r);
    r->gid = s->el[e].gid;
    memcpy(r->r.B, s->B[e], sizeof r->r.B);
    memcpy(r->r.Bs, s->Bs[e], sizeof r->r.Bs);
    r->r.bref = s->bref[e], r->r.bvar = s->bvar[e], r->r.open = s->open[e];
    memcpy(r->r.hist, s->hist[e], sizeof r->r.hist);
  }
  *out = (char *)g;
  *bytes = n * (int64_t)sizeof *g;
  return 1;
}

hr_status hr_solver_checkpoint(const hr_solver *s, const char *path, hr_err *err) {
  if (!s->started)
    return hr_err_set(err, HR_ERR_INVALID, "%s: nothing to save before the first iteration", path);
  /* Elements and links: this rank's own, and in a distributed run everybody's on rank 0, which
   * writes. */
  char *lb = NULL, *eb = NULL;
  int64_t lbytes = 0, ebytes = 0;
  hr_status st = pack_links(s, &lb, &lbytes) && pack_elements(s, &eb, &ebytes)
                     ? HR_OK
                     : hr_err_set(err, HR_ERR_NOMEM, "out of memory writing %s", path);
  if (s->dist && (st = hr_dist_agree(s, st, err)) == HR_OK) st = gather_links(s, &lb, &lbytes, err);
  if (s->dist && st == HR_OK) st = gather_links(s, &eb, &ebytes, err);
  /* the cluster links in the solver's order (its gather sums in that order): in a distributed
   * run everybody's, on rank 0, in the order they would have in one process */
  uint64_t *cids = NULL;
  float *cvals = NULL;
  int64_t ncl = 0;
  if (st == HR_OK && (st = hr_cluster_export(s, &cids, &cvals, &ncl)) != HR_OK)
    st = st == HR_ERR_REMOTE ? hr_err_set(err, st, "stopped: another rank failed")
                             : hr_err_set(err, HR_ERR_NOMEM, "out of memory writing %s", path);
  if (st != HR_OK || s->rank != 0) {
    free(lb), free(eb), free(cids), free(cvals);
    return st;
  }
  /* Canonical orders: gid for elements, (receiver gid, source gid, offset) for the live
   * links. */
  int64_t nl = 0, ne = ebytes / (int64_t)sizeof(gid_rec);
  gid_rec *ek = (gid_rec *)eb;
  qsort(ek, (size_t)ne, sizeof *ek, cmp_gid_rec);
  for (int64_t o = 0; o < lbytes; nl++) {
    link_rec r;
    memcpy(&r, lb + o, sizeof r);
    o += (int64_t)sizeof r + 4 * (int64_t)(r.ncand > 0 ? r.ncand : 0);
  }
  uint64_t(*lk)[3] = malloc((size_t)(nl > 0 ? nl : 1) * sizeof *lk);
  char tmp[4200];
  snprintf(tmp, sizeof tmp, "%s.tmp", path);
  writer w = {NULL, 0, 0};
  if (!lk) {
    free(eb);
    free(lb);
    free(cids), free(cvals);
    return hr_err_set(err, HR_ERR_NOMEM, "out of memory writing %s", path);
  }
  for (int64_t o = 0, i = 0; o < lbytes; i++) {
    link_rec r;
    memcpy(&r, lb + o, sizeof r);
    lk[i][0] = r.r, lk[i][1] = r.s, lk[i][2] = (uint64_t)o;
    o += (int64_t)sizeof r + 4 * (int64_t)(r.ncand > 0 ? r.ncand : 0);
  }
  qsort(lk, (size_t)nl, sizeof *lk, cmp_link_key);
  w.f = fopen(tmp, "wb");
  if (!w.f) {
    free(eb);
    free(lk);
    free(lb);
    free(cids), free(cvals);
    return hr_err_set(err, HR_ERR_IO, "%s: cannot write: %s", tmp, strerror(errno));
  }
  const uint32_t version = VERSION;
  const uint64_t hs = scene_hash(s->scene), ho = options_hash(&s->opt, s->scene->nsurfs);
  put(&w, MAGIC, 8);
  put(&w, &version, sizeof version);
  put(&w, &hs, sizeof hs);
  put(&w, &ho, sizeof ho);
  /* counts over all ranks */
  const int64_t rays = s->dist ? s->g_rays : s->rays;
  const int64_t init = s->dist ? s->g_initial : s->initial_links;
  progress pr = {s->iterations, s->converged, s->done,        s->stopped,
                 s->lazy,       s->xwin,      s->xlast,       0,
                 s->bf_e,       s->unit,      s->prev_change, s->stall_abs,
                 s->stall,      rays,         init,           s->t};
  put(&w, &pr, sizeof pr);
  put(&w, &ne, sizeof ne);
  for (int64_t i = 0; i < ne; i++) {
    put(&w, &ek[i].gid, sizeof ek[i].gid);
    put(&w, &ek[i].r, sizeof ek[i].r);
  }
  put(&w, &nl, sizeof nl);
  for (int64_t i = 0; i < nl; i++) {
    link_rec r;
    memcpy(&r, lb + lk[i][2], sizeof r);
    put(&w, &r, sizeof r);
    if (r.ncand > 0) put(&w, lb + lk[i][2] + sizeof r, (size_t)r.ncand * sizeof(int32_t));
  }
  /* cluster links, in the solver's order (its gather sums in that order) */
  put(&w, &ncl, sizeof ncl);
  if (ncl > 0) {
    put(&w, cids, (size_t)ncl * 2 * sizeof *cids);
    put(&w, cvals, (size_t)ncl * 8 * sizeof *cvals);
  }
  free(cids), free(cvals);
  const uint64_t sum = w.h;
  put(&w, &sum, sizeof sum);
  free(eb);
  free(lk);
  free(lb);
  int bad = w.bad || fflush(w.f) != 0 || ferror(w.f);
  if (fclose(w.f) != 0) bad = 1;
  if (bad || rename(tmp, path) != 0) {
    int e = errno;
    remove(tmp);
    return hr_err_set(err, HR_ERR_IO, "%s: cannot write the checkpoint: %s", path, strerror(e));
  }
  return HR_OK;
}

/* ---------------------------------------------------------------- reading */

typedef struct reader {
  const unsigned char *p, *end;
  uint64_t h;
  int bad;
} reader;

static void get(reader *r, void *out, size_t n) {
  if (r->bad || (size_t)(r->end - r->p) < n) {
    r->bad = 1;
    memset(out, 0, n);
    return;
  }
  memcpy(out, r->p, n);
  r->h = hash_bytes(r->h, r->p, n);
  r->p += n;
}

/* Reads past n bytes as get() would read them: one piece of the checksum. */
static void skip(reader *r, size_t n) {
  if (r->bad || (size_t)(r->end - r->p) < n) {
    r->bad = 1;
    return;
  }
  r->h = hash_bytes(r->h, r->p, n);
  r->p += n;
}

/* Reads the whole file; NULL with a message on failure. */
static unsigned char *slurp(const char *path, size_t *len, hr_err *err) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    hr_err_set(err, HR_ERR_IO, "%s: cannot read: %s", path, strerror(errno));
    return NULL;
  }
  unsigned char *buf = NULL;
  size_t n = 0, cap = 0;
  for (;;) {
    if (n == cap) {
      size_t nc = cap ? 2 * cap : 1 << 20;
      unsigned char *b = realloc(buf, nc);
      if (!b) {
        free(buf);
        fclose(f);
        hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
        return NULL;
      }
      buf = b, cap = nc;
    }
    size_t got = fread(buf + n, 1, cap - n, f);
    n += got;
    if (got == 0) break;
  }
  int bad = ferror(f);
  fclose(f);
  if (bad) {
    free(buf);
    hr_err_set(err, HR_ERR_IO, "%s: read error", path);
    return NULL;
  }
  *len = n;
  return buf;
}

/* Creates (by subdividing its parent, which exists) the element with gid 'g'; its index, or -1
 * when the gid cannot be an element of this scene. */
static int32_t make_element(hr_solver *s, uint64_t g) {
  const uint64_t pathmask = (UINT64_C(1) << HR_GID_PATH_BITS) - 1;
  const uint64_t heap = g & pathmask, surf = g >> HR_GID_PATH_BITS;
  if (surf >= (uint64_t)s->scene->nsurfs || heap < 4) return -1;
  const int32_t parent = hr_elem_find(s, (g & ~pathmask) | (heap >> 2));
  if (parent < 0) return -1;
  if (s->el[parent].child < 0 && hr_elem_subdivide(s, parent) != HR_OK) return -2;
  if (s->el[parent].child < 0) return -1;
  return s->el[parent].child + (int32_t)(heap & 3);
}

/* Reads the elements; 0 on a damaged file (message set), -1 when out of memory. */
static int read_elements(hr_solver *s, reader *r, const char *path, hr_err *err) {
  int64_t n;
  get(r, &n, sizeof n);
  if (r->bad || n < s->scene->nsurfs || n > (int64_t)(r->end - r->p)) {
    hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (element count)", path);
    return 0;
  }
  for (int64_t i = 0; i < n; i++) {
    uint64_t g;
    elem_rec er;
    get(r, &g, sizeof g);
    get(r, &er, sizeof er);
    if (r->bad) break;
    int32_t e = hr_elem_find(s, g);
    if (e < 0) e = make_element(s, g);
    if (e == -2) return -1;
    if (e < 0) {
      hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (element %llx)", path,
                 (unsigned long long)g);
      return 0;
    }
    memcpy(s->B[e], er.B, sizeof er.B);
    memcpy(s->Bs[e], er.Bs, sizeof er.Bs);
    s->bref[e] = er.bref, s->bvar[e] = er.bvar, s->open[e] = er.open;
    memcpy(s->hist[e], er.hist, sizeof er.hist);
  }
  if (r->bad || s->nel != n) {
    hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (elements)", path);
    return 0;
  }
  return 1;
}

/* Reads the links into s->links and s->pool; 0 on a damaged file, -1 when out of memory. */
static int read_links(hr_solver *s, reader *r, const char *path, hr_err *err) {
  int64_t n;
  get(r, &n, sizeof n);
  if (r->bad || n < 0 || n > (int64_t)(r->end - r->p) / (int64_t)sizeof(link_rec)) {
    hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (link count)", path);
    return 0;
  }
  s->links = malloc((size_t)(n > 0 ? n : 1) * sizeof *s->links);
  if (!s->links) return -1;
  s->cap_links = n > 0 ? n : 1;
  s->nlinks = 0;
  for (int64_t i = 0; i < n; i++) {
    link_rec lr;
    get(r, &lr, sizeof lr);
    const int32_t ri = hr_elem_find(s, lr.r), si = hr_elem_find(s, lr.s);
    if (r->bad || ri < 0 || si < 0 || lr.ncand < -1 ||
        (lr.ncand > 0 && (size_t)lr.ncand > (size_t)(r->end - r->p) / sizeof(int32_t))) {
      hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (link %lld)", path, (long long)i);
      return 0;
    }
    if (!hr_owns(s, ri)) { /* another rank's: read past it (the checksum covers it) */
      if (lr.ncand > 0) skip(r, (size_t)lr.ncand * sizeof(int32_t));
      continue;
    }
    hr_link *l = &s->links[s->nlinks];
    *l = (hr_link){.r = ri, .s = si, .F = lr.F, .Fu = lr.Fu, .dF = lr.dF, .dS = lr.dS,
                   .cand_off = 0, .ncand = lr.ncand};
    memcpy(l->w, lr.w, sizeof l->w);
    if (lr.ncand > 0) {
      if (s->npool + lr.ncand > (int64_t)UINT32_MAX) return -1;
      if (s->npool + lr.ncand > s->cap_pool) {
        int64_t nc = s->cap_pool ? 2 * s->cap_pool : 1024;
        while (nc < s->npool + lr.ncand) nc *= 2;
        int32_t *p = realloc(s->pool, (size_t)nc * sizeof *p);
        if (!p) return -1;
        s->pool = p, s->cap_pool = nc;
      }
      get(r, s->pool + s->npool, (size_t)lr.ncand * sizeof(int32_t));
      for (int32_t k = 0; k < lr.ncand; k++)
        if (s->pool[s->npool + k] < 0 || s->pool[s->npool + k] >= s->scene->nsurfs) r->bad = 1;
      l->cand_off = (uint32_t)s->npool;
      s->npool += lr.ncand;
    }
    s->nlinks++;
  }
  if (r->bad) {
    hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (links)", path);
    return 0;
  }
  return 1;
}

/* The cluster links: none unless the solver clusters, whose hierarchy is built here. */
static int read_clusters(hr_solver *s, reader *r, const char *path, hr_err *err) {
  int64_t n;
  get(r, &n, sizeof n);
  const int64_t rec = 2 * (int64_t)sizeof(uint64_t) + 8 * (int64_t)sizeof(float);
  if (r->bad || n < 0 || n > (int64_t)(r->end - r->p) / rec || (n > 0) != hr_solver_clustered(s)) {
    hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (cluster link count)", path);
    return 0;
  }
  if (!hr_solver_clustered(s)) return 1;
  uint64_t *ids = malloc((size_t)n * 2 * sizeof *ids);
  float *vals = malloc((size_t)n * 8 * sizeof *vals);
  if (!ids || !vals) {
    free(ids), free(vals);
    return -1;
  }
  get(r, ids, (size_t)n * 2 * sizeof *ids);
  get(r, vals, (size_t)n * 8 * sizeof *vals);
  hr_status st = r->bad ? HR_ERR_PARSE : hr_cluster_import(s, ids, vals, n);
  free(ids), free(vals);
  if (st == HR_ERR_NOMEM) return -1;
  if (st != HR_OK) {
    hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (cluster links)", path);
    return 0;
  }
  return 1;
}

static hr_status resume(hr_solver *s, const char *path, hr_err *err);

hr_status hr_solver_resume(hr_solver *s, const char *path, hr_err *err) {
  hr_status st = resume(s, path, err);
  if (!s->dist) return st;
  /* every rank read the same file: only a local failure (memory) can differ */
  if ((st = hr_dist_agree(s, st, err)) != HR_OK) return st;
  /* the file's counts are totals over the ranks: rank 0 carries them */
  if (s->rank != 0) s->rays = 0, s->initial_links = 0;
  hr_solver_sync_counts(s);
  /* every rank built every element from the file: it keeps its own, the sources of its links,
   * their children, and what the tree needs above them; its ghosts of sources subscribe */
  hr_elem_prune(s);
  return hr_link_subscribe(s, err);
}

/* hr_solver_resume on this rank: elements, state, and the links of the elements it owns. */
static hr_status resume(hr_solver *s, const char *path, hr_err *err) {
  if (s->started || s->nel != s->scene->nsurfs)
    return hr_err_set(err, HR_ERR_INVALID, "%s: resume needs a solver that has not run", path);
  size_t len = 0;
  unsigned char *buf = slurp(path, &len, err);
  if (!buf) return HR_ERR_IO;
  reader r = {buf, buf + len, 0, 0};
  char magic[8];
  uint32_t version;
  uint64_t hs, ho;
  get(&r, magic, 8);
  get(&r, &version, sizeof version);
  get(&r, &hs, sizeof hs);
  get(&r, &ho, sizeof ho);
  hr_status st = HR_OK;
  /* The checksum (of every piece the writer put, in its pieces) is checked at the end. */
  uint64_t sum = 0;
  if (len >= 8) memcpy(&sum, buf + len - 8, 8);
  if (r.bad || memcmp(magic, MAGIC, 8) != 0) {
    st = hr_err_set(err, HR_ERR_PARSE, "%s: not an hrad checkpoint", path);
  } else if (version != VERSION) {
    st = hr_err_set(err, HR_ERR_PARSE, "%s: checkpoint version %u, this hrad reads %u", path,
                    version, VERSION);
  } else if (hs != scene_hash(s->scene)) {
    st = hr_err_set(err, HR_ERR_INVALID, "%s: the checkpoint was written for another scene",
                    path);
  } else if (ho != options_hash(&s->opt, s->scene->nsurfs)) {
    st = hr_err_set(err, HR_ERR_INVALID,
                    "%s: the checkpoint was written with other solver options (--bf-low, "
                    "--area-min, --rays, --seed, --cluster, ...): resume with the same ones",
                    path);
  }
  progress pr;
  if (st == HR_OK) {
    r.end = buf + len - 8; /* the checksum is not part of the content */
    get(&r, &pr, sizeof pr);
    int ok = r.bad ? 0 : read_elements(s, &r, path, err);
    if (ok > 0) ok = read_links(s, &r, path, err);
    if (ok > 0) ok = read_clusters(s, &r, path, err);
    if (ok < 0)
      st = hr_err_set(err, HR_ERR_NOMEM, "%s: out of memory", path);
    else if (ok == 0)
      st = HR_ERR_PARSE; /* message set */
    else if (r.p != r.end || r.h != sum)
      st = hr_err_set(err, HR_ERR_PARSE, "%s: damaged checkpoint (checksum)", path);
  }
  free(buf);
  if (st != HR_OK) return st;
  s->iterations = pr.iterations, s->converged = pr.converged, s->done = pr.done;
  s->stopped = pr.stopped, s->lazy = pr.lazy, s->bf_e = pr.bf_e, s->unit = pr.unit;
  s->xwin = pr.xwin, s->xlast = pr.xlast;
  s->rays = pr.rays;
  s->prev_change = pr.prev_change, s->stall_abs = pr.stall_abs, s->stall = pr.stall;
  s->initial_links = pr.initial_links, s->t = pr.t;
  s->started = 1;
  /* A run that stopped without converging (max_iters, or its callback) goes on when this
   * solver's max_iters allows more iterations. */
  if (s->done && !s->converged && s->iterations < s->opt.max_iters) s->done = s->stopped = 0;
  s->sorted = 0; /* the next hr_link_sort groups the links afresh */
  s->nsorted = s->ndead = 0;
  return HR_OK;
}
