/* cluster.h: hierarchical clustering (issue 12; Smits, Arvo & Greenberg 1994, Sillion 1995): a
 * binary hierarchy of volume clusters above the surface roots, and cluster links between
 * clusters and surfaces, so that linking starts from one self-link of the root cluster and costs
 * about O(n log n) instead of O(n^2) surface pairs. Internal API; docs/design.md "Clustering".
 *
 * A node is an int32: >= 0 a surface root (element idx == surface id), < 0 cluster -1-c. Cluster
 * links only ever open clusters; a link between two surfaces becomes an ordinary element link
 * (link.c) and refines as one. */
#ifndef HR_CLUSTER_H
#define HR_CLUSTER_H

#include "hrad.h"

#include <stddef.h>
#include <stdint.h>

typedef struct hr_solver hr_solver;
typedef struct hr_clusters hr_clusters;

/* A cluster's global id is HR_CLUSTER_GID | c (checkpoints, graph balancing's maps and graph
 * file); an element's never has this bit. */
#define HR_CLUSTER_GID (UINT64_C(1) << 63)

/* 1 when the solver clusters: --cluster on, or auto with more surface pairs than max_links. */
int hr_cluster_wanted(const hr_options *o, int nsurfs);

/* Builds the hierarchy over the scene's surfaces and the root's self-link, and refines the
 * cluster links at the first BF_e (element links between surfaces go to s->links). */
/* What the iterations need beyond the hierarchy and links (the surfaces' transfer vectors):
 * once the ray caster exists; nothing without clusters. */
hr_status hr_cluster_prepare(hr_solver *s, hr_err *err);
hr_status hr_cluster_init(hr_solver *s, hr_err *err);
/* One refinement pass of the cluster links at 'bf_e'; adds the new links (cluster and element)
 * to '*nnew'. New element links make the next hr_link_sort a full one. */
hr_status hr_cluster_refine(hr_solver *s, double bf_e, int64_t *nnew, hr_err *err);
/* After the element gather: adds what the cluster links bring to G, Gu and Gf of the surface
 * roots (through the clusters' incident fields). A collective in distributed runs. */
void hr_cluster_gather(hr_solver *s);
/* After push-pull: the clusters' radiosities, ranges and reference radiosities from the roots
 * (in distributed runs every rank's roots are current: push-pull shares them). */
void hr_cluster_pull(hr_solver *s);
/* Checkpoints: the cluster links in their order, each as two node ids (an element's gid, or
 * 1 << 63 | cluster) and eight floats; hr_cluster_export allocates both arrays (NULL when
 * there are none; in distributed runs a collective that brings every rank's links to rank 0,
 * HR_ERR_REMOTE where another rank failed). hr_cluster_import builds the hierarchy of a resumed
 * solver and takes the links (elements must exist already; a rank keeps the links whose
 * receivers it holds the links of); HR_ERR_PARSE for an id that names no node. */
hr_status hr_cluster_export(const hr_solver *s, uint64_t **ids, float **vals, int64_t *n);
hr_status hr_cluster_import(hr_solver *s, const uint64_t *ids, const float *vals, int64_t n);
int64_t hr_cluster_links(const hr_solver *s); /* this rank's */
/* Adds to recv[e] the count of this rank's cluster links that element e receives (graph
 * balancing's work weights, balance.c). */
void hr_cluster_recv_counts(const hr_solver *s, int64_t *recv);
/* Graph balancing's view of the clusters (balance.c; the graph file of --dump-graph). For each
 * cluster c < hr_cluster_count: its gid (1 << 63 | c), its parent's (0 for the root), its
 * centre, whether this rank holds the links it receives, and those links and the rays
 * refinement cast for them here; above[e] gets the gid of the cluster directly above surface
 * root e (for e < the scene's surfaces). 1, 0 without clusters, -1 when out of memory. */
typedef struct hr_cluster_node {
  uint64_t gid, parent;
  double xyz[3], rays;
  int64_t recv;
  int mine;
} hr_cluster_node;
int hr_cluster_graph(const hr_solver *s, hr_cluster_node *out, uint64_t *above);
/* The rank that holds the links cluster c receives. */
int hr_cluster_owner(const hr_solver *s, int32_t c);
/* Graph balancing's new owners of clusters: the entries of a subtree map (gids, ranks; n)
 * whose gid names a cluster (1 << 63 | c) set c's owner; the others are left to the elements'
 * map. Then hr_cluster_migrate sends the links. 0 for a gid that names no cluster. */
int hr_cluster_set_owners(hr_solver *s, const uint64_t *gids, const int32_t *ranks, int64_t n);
/* This rank's cluster links from a surface to a cluster, as (receiver gid, source gid) pairs
 * into e (room for hr_cluster_links of them): the ones whose source a receiver's rank must
 * hold a copy of. Links from clusters need none: the clusters' state is on every rank.
 * Returns the count. */
int64_t hr_cluster_elem_sources(const hr_solver *s, uint64_t (*e)[2]);
size_t hr_cluster_link_bytes(const hr_solver *s); /* what one cluster link takes */
int64_t hr_cluster_count(const hr_solver *s);
void hr_cluster_free(hr_clusters **c);

/* Distributed runs (docs/design.md, "Clustering"). A cluster link lives on the rank that owns
 * its receiver (an element's owner; a cluster's is drawn from its number).
 * hr_cluster_sources: the ghost sources of this rank's cluster links not subscribed yet, in a
 * new array. hr_cluster_migrate (a collective): after element owners changed, the links of
 * elements that moved go to their new owners. hr_cluster_keep marks the elements at the ends of
 * cluster links in 'keep' (hr_elem_prune); hr_cluster_renumber follows hr_elem_compact's new
 * indices 'nu'. */
hr_status hr_cluster_sources(const hr_solver *s, int32_t **out, int64_t *n);
hr_status hr_cluster_migrate(hr_solver *s, hr_err *err);
void hr_cluster_keep(const hr_solver *s, uint8_t *keep);
void hr_cluster_renumber(hr_solver *s, const int32_t *nu);

/* Order-2 real spherical harmonics of the unit vector d (9 values, Ramamoorthi & Hanrahan's
 * ordering: 00, 1-1, 10, 11, 2-2, 2-1, 20, 21, 22). */
void hr_sh9(const double d[3], double y[9]);
/* The clamped-cosine convolution weights A_l for l = 0, 1, 2: pi, 2 pi / 3, pi / 4. */
extern const double hr_sh_alpha[9];

#endif
