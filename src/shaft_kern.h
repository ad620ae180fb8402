/* shaft_kern.h: the shaft construction and tests of shaft.c and the loops that use them,
 * included twice by shaft.c: once for the x86-64 baseline and, on x86, once more with
 * KERN_AVX2 1, where every function is compiled for AVX2 (KERN_ATTR) and the plane tests run 4
 * at a time in AVX2 registers. KERN(name) gives each instance its own names; shaft.c chooses one
 * at run time. Both give the same answers bit for bit (the same operations in the same order,
 * no fused multiply-adds). Not a header of its own: only shaft.c includes it. */

/* Smallest and largest of n.p - d over the points. */
KERN_ATTR static inline void KERN(pts8_range)(const pts8 *p, hr_vec3 n, double d, double *mn,
                                               double *mx) {
#if KERN_AVX2
  const __m256d vx = _mm256_set1_pd(n.x), vy = _mm256_set1_pd(n.y), vz = _mm256_set1_pd(n.z),
                vd = _mm256_set1_pd(d);
  __m256d s0 = _mm256_add_pd(_mm256_mul_pd(vx, _mm256_loadu_pd(p->x)),
                             _mm256_mul_pd(vy, _mm256_loadu_pd(p->y)));
  __m256d s1 = _mm256_add_pd(_mm256_mul_pd(vx, _mm256_loadu_pd(p->x + 4)),
                             _mm256_mul_pd(vy, _mm256_loadu_pd(p->y + 4)));
  s0 = _mm256_sub_pd(_mm256_add_pd(s0, _mm256_mul_pd(vz, _mm256_loadu_pd(p->z))), vd);
  s1 = _mm256_sub_pd(_mm256_add_pd(s1, _mm256_mul_pd(vz, _mm256_loadu_pd(p->z + 4))), vd);
  __m256d lo = _mm256_min_pd(s0, s1), hi = _mm256_max_pd(s0, s1);
  __m128d lo2 = _mm_min_pd(_mm256_castpd256_pd128(lo), _mm256_extractf128_pd(lo, 1));
  __m128d hi2 = _mm_max_pd(_mm256_castpd256_pd128(hi), _mm256_extractf128_pd(hi, 1));
  *mn = _mm_cvtsd_f64(_mm_min_sd(lo2, _mm_unpackhi_pd(lo2, lo2)));
  *mx = _mm_cvtsd_f64(_mm_max_sd(hi2, _mm_unpackhi_pd(hi2, hi2)));
#else
  double a = INFINITY, b = -INFINITY;
  for (int i = 0; i < 8; i++) {
    double s = n.x * p->x[i] + n.y * p->y[i] + n.z * p->z[i] - d;
    a = s < a ? s : a;
    b = s > b ? s : b;
  }
  *mn = a;
  *mx = b;
#endif
}

KERN_ATTR static void KERN(add_plane_if_bounding)(shaft_t *sh, hr_vec3 n, hr_vec3 at,
                                                  const pts8 *pts,
                                  double tol) {
  double len2 = v3_dot(n, n);
  if (!(len2 > 0) || !isfinite(len2)) return;
  /* Signed distances times |n| first (no square root for the many rejected planes). */
  double d = v3_dot(n, at), mn, mx;
  KERN(pts8_range)(pts, n, d, &mn, &mx);
  double len = sqrt(len2), tl = tol * len;
  if (!(mx <= tl) && !(mn >= -tl)) return;
  double inv = 1.0 / len;
  n = v3_scale(n, inv);
  d *= inv, mn *= inv, mx *= inv;
  /* All points within 'tol' on the negative side: n.x <= d + tol bounds them (and the exact
   * hull, since it is the convex hull of these points). Likewise for the positive side. */
  if (mx <= tol) push_plane(sh, n, d + (mx > 0 ? mx : 0) + tol);
  if (mn >= -tol) push_plane(sh, v3_scale(n, -1), -d + (mn < 0 ? -mn : 0) + tol);
}

/* Adds the front half-space of polygon 'v' (always: by definition of the shaft) and its back
 * half-space when every point lies behind or on its plane (coplanar or back-to-back pairs). */
KERN_ATTR static int KERN(add_own_plane)(shaft_t *sh, const hr_vec3 *v, int nv, const pts8 *pts,
                                         double tol) {
  hr_vec3 n = v3_newell(v, nv);
  double len = v3_len(n);
  if (!(len > 0) || !isfinite(len)) return 1;
  n = v3_scale(n, 1.0 / len);
  double d = 0;
  for (int i = 0; i < nv; i++) d += v3_dot(n, v[i]);
  d /= nv;
  double mx, pmn = INFINITY, pmx = -INFINITY;
  for (int i = 0; i < nv; i++) {
    double s = v3_dot(n, v[i]) - d;
    pmn = s < pmn ? s : pmn;
    pmx = s > pmx ? s : pmx;
  }
  double mn_unused;
  KERN(pts8_range)(pts, n, d, &mn_unused, &mx);
  push_plane(sh, v3_scale(n, -1), -(d + pmn) + tol); /* front: n.x >= d + pmn - tol */
  if (mx <= (pmx > 0 ? pmx : 0) + tol) {
    push_plane(sh, n, d + (mx > 0 ? mx : 0) + tol); /* back */
    return 1;
  }
  return 0;
}

KERN_ATTR static void KERN(shaft_build)(shaft_t *sh, const hr_vec3 *pa, int na, const hr_vec3 *pb,
                                        int nb) {
  hr_vec3 pts[8];
  int npts = 0;
  sh->np = 0;
  for (int i = 0; i < na && npts < 8; i++) pts[npts++] = pa[i];
  for (int i = 0; i < nb && npts < 8; i++) pts[npts++] = pb[i];
  if (npts == 0) { /* no half-spaces: everything is a candidate */
    for (int a = 0; a < 3; a++) sh->lo[a] = -INFINITY, sh->hi[a] = INFINITY;
    return;
  }
  hr_vec3 lo = v3(INFINITY, INFINITY, INFINITY), hi = v3(-INFINITY, -INFINITY, -INFINITY);
  for (int i = 0; i < npts; i++) {
    lo = v3_min(lo, pts[i]);
    hi = v3_max(hi, pts[i]);
  }
  double mag = fmax(fmax(fmax(fabs(lo.x), fabs(hi.x)), fmax(fabs(lo.y), fabs(hi.y))),
                    fmax(fabs(lo.z), fabs(hi.z)));
  mag = fmax(mag, v3_len(v3_sub(hi, lo)));
  double tol = SHAFT_REL_TOL * mag;
  /* The box of both polygons: tested first, scalar; the best discriminator for far nodes. */
  sh->lo[0] = lo.x - tol, sh->lo[1] = lo.y - tol, sh->lo[2] = lo.z - tol;
  sh->hi[0] = hi.x + tol, sh->hi[1] = hi.y + tol, sh->hi[2] = hi.z + tol;
  /* 'flat': all points on or behind a polygon's plane (coplanar or back-to-back pair). */
  pts8 p8;
  for (int i = 0; i < 8; i++) {
    hr_vec3 q = pts[i < npts ? i : npts - 1];
    p8.x[i] = q.x, p8.y[i] = q.y, p8.z[i] = q.z;
  }
  int flat = KERN(add_own_plane)(sh, pa, na, &p8, tol);
  flat |= KERN(add_own_plane)(sh, pb, nb, &p8, tol);
  /* Hull faces through an edge of one polygon and a vertex of the other. */
  for (int side = 0; side < 2; side++) {
    const hr_vec3 *p = side ? pb : pa, *q = side ? pa : pb;
    int np = side ? nb : na, nq = side ? na : nb;
    for (int i = 0; i < np; i++) {
      hr_vec3 a = p[i], e = v3_sub(p[(i + 1) % np], a);
      for (int j = 0; j < nq; j++)
        KERN(add_plane_if_bounding)(sh, v3_cross(e, v3_sub(q[j], a)), a, &p8, tol);
    }
  }
  /* An edge and its polygon's normal: the hull's sides when both polygons are coplanar. Other
   * pairs need none: every face of the hull of two convex planar polygons that are not flat is
   * a polygon's own plane or holds an edge of one polygon and a vertex of the other. */
  for (int side = 0; side < 2 && flat; side++) {
    const hr_vec3 *p = side ? pb : pa;
    int np = side ? nb : na;
    hr_vec3 nrm = v3_newell(p, np);
    for (int i = 0; i < np; i++) {
      hr_vec3 a = p[i], e = v3_sub(p[(i + 1) % np], a);
      KERN(add_plane_if_bounding)(sh, v3_cross(e, nrm), a, &p8, tol);
    }
  }
  const double slack = 1e-9 * mag;
  for (int k = 0; k < sh->np; k++) {
    sh->ax[k] = fabs(sh->nx[k]);
    sh->ay[k] = fabs(sh->ny[k]);
    sh->az[k] = fabs(sh->nz[k]);
    sh->dn[k] = sh->d[k] + slack;
    sh->ds[k] = flat ? sh->d[k] : sh->d[k] - 2 * tol;
  }
  /* Pad to a multiple of 4 with copies of the first plane (same answers, whole vectors). */
  while (sh->np % 4 && sh->np > 0) {
    int k = sh->np++;
    sh->nx[k] = sh->nx[0], sh->ny[k] = sh->ny[0], sh->nz[k] = sh->nz[0], sh->d[k] = sh->d[0];
    sh->ax[k] = sh->ax[0], sh->ay[k] = sh->ay[0], sh->az[k] = sh->az[0], sh->dn[k] = sh->dn[0];
    sh->ds[k] = sh->ds[0];
  }
}

/* 1 when the box [lo,hi] may intersect the shaft: no plane has the whole box outside. */
KERN_ATTR static inline int KERN(box_in_shaft)(const shaft_t *sh, const double lo[3],
                                               const double hi[3]) {
  if (lo[0] > sh->hi[0] || hi[0] < sh->lo[0] || lo[1] > sh->hi[1] || hi[1] < sh->lo[1] ||
      lo[2] > sh->hi[2] || hi[2] < sh->lo[2])
    return 0;
  const double cx = 0.5 * (lo[0] + hi[0]), cy = 0.5 * (lo[1] + hi[1]), cz = 0.5 * (lo[2] + hi[2]);
  const double hx = 0.5 * (hi[0] - lo[0]), hy = 0.5 * (hi[1] - lo[1]), hz = 0.5 * (hi[2] - lo[2]);
#if KERN_AVX2
  const __m256d vcx = _mm256_set1_pd(cx), vcy = _mm256_set1_pd(cy), vcz = _mm256_set1_pd(cz);
  const __m256d vhx = _mm256_set1_pd(hx), vhy = _mm256_set1_pd(hy), vhz = _mm256_set1_pd(hz);
  __m256d acc = _mm256_setzero_pd();
  for (int k = 0; k < sh->np; k += 4) {
    __m256d m = _mm256_mul_pd(_mm256_loadu_pd(sh->nx + k), vcx);
    m = _mm256_add_pd(m, _mm256_mul_pd(_mm256_loadu_pd(sh->ny + k), vcy));
    m = _mm256_add_pd(m, _mm256_mul_pd(_mm256_loadu_pd(sh->nz + k), vcz));
    __m256d r = _mm256_mul_pd(_mm256_loadu_pd(sh->ax + k), vhx);
    r = _mm256_add_pd(r, _mm256_mul_pd(_mm256_loadu_pd(sh->ay + k), vhy));
    r = _mm256_add_pd(r, _mm256_mul_pd(_mm256_loadu_pd(sh->az + k), vhz));
    acc = _mm256_or_pd(acc,
                       _mm256_cmp_pd(_mm256_sub_pd(m, r), _mm256_loadu_pd(sh->dn + k), _CMP_GT_OQ));
  }
  return _mm256_movemask_pd(acc) == 0;
#else
  int out = 0;
  for (int k = 0; k < sh->np; k++)
    out |= sh->nx[k] * cx + sh->ny[k] * cy + sh->nz[k] * cz -
               (sh->ax[k] * hx + sh->ay[k] * hy + sh->az[k] * hz) >
           sh->dn[k];
  return !out;
#endif
}

/* 1 when surface 'f' may intersect the shaft: no plane has all its vertices outside it or on
 * it (within the tolerance; see shaft_t.ds). */
KERN_ATTR static inline int KERN(surf_in_shaft)(const shaft_t *sh, const hr_surface *f) {
  const hr_vec3 *v = f->v;
  const int nv = f->nverts;
  double lo[3] = {v[0].x, v[0].y, v[0].z}, hi[3] = {v[0].x, v[0].y, v[0].z};
  for (int j = 1; j < nv; j++) {
    lo[0] = v[j].x < lo[0] ? v[j].x : lo[0], hi[0] = v[j].x > hi[0] ? v[j].x : hi[0];
    lo[1] = v[j].y < lo[1] ? v[j].y : lo[1], hi[1] = v[j].y > hi[1] ? v[j].y : hi[1];
    lo[2] = v[j].z < lo[2] ? v[j].z : lo[2], hi[2] = v[j].z > hi[2] ? v[j].z : hi[2];
  }
  if (lo[0] > sh->hi[0] || hi[0] < sh->lo[0] || lo[1] > sh->hi[1] || hi[1] < sh->lo[1] ||
      lo[2] > sh->hi[2] || hi[2] < sh->lo[2])
    return 0;
#if KERN_AVX2
  __m256d acc = _mm256_setzero_pd();
  for (int k = 0; k < sh->np; k += 4) {
    const __m256d nx = _mm256_loadu_pd(sh->nx + k), ny = _mm256_loadu_pd(sh->ny + k),
                  nz = _mm256_loadu_pd(sh->nz + k), d = _mm256_loadu_pd(sh->ds + k);
    __m256d all = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    for (int j = 0; j < nv; j++) {
      __m256d m = _mm256_mul_pd(nx, _mm256_set1_pd(v[j].x));
      m = _mm256_add_pd(m, _mm256_mul_pd(ny, _mm256_set1_pd(v[j].y)));
      m = _mm256_add_pd(m, _mm256_mul_pd(nz, _mm256_set1_pd(v[j].z)));
      all = _mm256_and_pd(all, _mm256_cmp_pd(m, d, _CMP_GT_OQ));
    }
    acc = _mm256_or_pd(acc, all);
  }
  return _mm256_movemask_pd(acc) == 0;
#else
  int out = 0;
  for (int k = 0; k < sh->np; k++) {
    int o = 1;
    for (int j = 0; j < nv; j++)
      o &= sh->nx[k] * v[j].x + sh->ny[k] * v[j].y + sh->nz[k] * v[j].z > sh->ds[k];
    out |= o;
  }
  return !out;
#endif
}

/* ------------------------------------------------------------------ the loops */

/* hr_shaft_candidates for a non-empty index: the candidates, unsorted. */
KERN_ATTR static hr_status KERN(candidates)(const hr_shaft_index *x, const hr_vec3 *pa, int na,
                                           int sa, const hr_vec3 *pb, int nb, int sb,
                                           int32_t **out, int *nout, int *cap) {
  shaft_t sh;
  KERN(shaft_build)(&sh, pa, na, pb, nb);
  const hr_scene *s = x->s;
  for (int i = 0; i < x->nnodes;) {
    const bvh_node *nd = &x->nodes[i];
    if (!KERN(box_in_shaft)(&sh, nd->lo, nd->hi)) {
      i = nd->skip;
      continue;
    }
    if (nd->count > 0) {
      for (int k = nd->first; k < nd->first + nd->count; k++) {
        int id = x->perm[k];
        if (id == sa || id == sb) continue;
        if (!KERN(box_in_shaft)(&sh, x->sbox + 6 * k, x->sbox + 6 * k + 3)) continue;
        if (KERN(surf_in_shaft)(&sh, &s->surfs[id]) && !push_id(out, nout, cap, id))
          return HR_ERR_NOMEM;
      }
    }
    i++;
  }
  return HR_OK;
}

/* hr_shaft_filter. */
KERN_ATTR static int KERN(filter)(const hr_scene *s, const hr_vec3 *pa, int na, int sa,
                                 const hr_vec3 *pb, int nb, int sb, const int32_t *cand,
                                 int ncand, int32_t *out) {
  shaft_t sh;
  KERN(shaft_build)(&sh, pa, na, pb, nb);
  int m = 0;
  for (int j = 0; j < ncand; j++) {
    int id = cand[j];
    if (id == sa || id == sb || id < 0 || id >= s->nsurfs) continue;
    if (KERN(surf_in_shaft)(&sh, &s->surfs[id])) out[m++] = id;
  }
  return m;
}
