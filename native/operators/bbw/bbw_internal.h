/* DeformKit: bounded biharmonic weights, what the steps of dk_bounded_biharmonic_weights
 * (bbw.c) hand each other: the handles' samples (handles.c), a domain (surface_domain.c,
 * volume_domain.c) and the weights on it (box_qp.c per handle). */
#ifndef DK_BBW_INTERNAL_H
#define DK_BBW_INTERNAL_H

#include "dk_bbw.h"
#include "dk_sparse.h"

#include <math.h>
#include <stddef.h>

/* A point where the weights are given: at most BBW_SAMPLE_HANDLES handles with non-zero
 * weight there (a point or bone sample: one handle, weight 1; a sample of a cage face: its
 * corners, barycentric; a joint where bones meet: each of them equally). */
#define BBW_SAMPLE_HANDLES 8
typedef struct bbw_sample {
    double p[3];
    dk_index handle[BBW_SAMPLE_HANDLES]; /* -1 for none                                  */
    double weight[BBW_SAMPLE_HANDLES];
    dk_index owner;     /* the handle whose sample it is (the first corner for a cage)   */
} bbw_sample;

/* Samples every handle at spacing `step` at most (points once, bones along their segment
 * with both ends and at least its midpoint, the cage's vertices, edges and faces). Samples
 * closer than 1e-6 step are one (a joint: the bones meeting there share it equally, the
 * first BBW_SAMPLE_HANDLES of them). *out malloc'ed. */
dk_status bbw_sample_handles(const dk_bbw_handles *h, double step, bbw_sample **out,
                             dk_index *n_out, dk_error *err);

/* The handle's name in messages: "point 2", "bone 0", "cage vertex 7" (buf of 48). */
const char *bbw_handle_name(const dk_bbw_handles *h, dk_index handle, char *buf);

/* The weights' domain: vertices, stiffness K and lumped mass M, the vertices held at given
 * weights, and how each mesh vertex reads its weights from the domain's (up to 4 domain
 * vertices and their barycentric weights). */
typedef struct bbw_domain {
    dk_bbw_domain kind;
    dk_index n;              /* domain vertices                                          */
    double *positions;       /* n x 3                                                    */
    dk_sparse *stiffness;    /* n x n, both triangles, PSD                               */
    double *mass;            /* n, > 0 where the vertex is in an element                 */
    dk_index n_elements;
    bbw_sample *samples;     /* the handles' samples                                     */
    dk_index n_samples;
    dk_index n_held;
    dk_index *held;          /* n_held domain vertices, distinct                         */
    dk_index *held_sample;   /* n_held: the sample each is held at                       */
    dk_index *tets;          /* VOLUME: n_elements x 4 domain vertices, else NULL        */
    double *frames;          /* VOLUME: n_elements x 12: corner 0, then the gradients of
                                the barycentric coordinates of corners 1..3               */
    double cell;             /* VOLUME: the grid's cell size h                           */
    dk_index *embed;         /* n_mesh x 4 domain vertices, -1 unused                    */
    double *embed_weight;    /* n_mesh x 4                                               */
} bbw_domain;

void bbw_domain_free(bbw_domain *d);

/* dk_box_qp, told whether the start x solves A x = b (all variables free): then a start
 * inside the box is the answer without a factorization; `simplicial`: factor without BLAS
 * (dk_cholesky_analyze_simplicial), for programs solved two at a time. */
dk_status bbw_box_qp(const dk_sparse *a, const double *b, double lo, double hi, double *x,
                     int start_solves, int simplicial, int max_iterations, int *iterations,
                     double *kkt_residual, dk_error *err);

/* A dense grid of cells of size h with a linked list of items per cell. */
typedef struct cell_grid {
    double origin[3], h;
    dk_index dim[3];
    dk_index *head; /* cells, -1 empty */
} cell_grid;

static inline dk_index cell_coord(const cell_grid *g, const double *p, int k)
{
    double c = floor((p[k] - g->origin[k]) / g->h);
    if (!(c >= 0.0)) return 0;
    if (c >= (double)g->dim[k]) return g->dim[k] - 1;
    return (dk_index)c;
}

static inline size_t cell_index(const cell_grid *g, dk_index x, dk_index y, dk_index z)
{
    return ((size_t)z * (size_t)g->dim[1] + (size_t)y) * (size_t)g->dim[0] + (size_t)x;
}

/* Where each of `n` points lies in the VOLUME domain `d`: the corners of its tetrahedron
 * (embed, n x 4) and its barycentric coordinates there (w, n x 4); a point outside every
 * tetrahedron gets the nearest one it meets within a cell, its coordinates clamped to >= 0
 * and renormalised, and beyond that the nearest domain vertex (weight 1). */
dk_status bbw_locate(const bbw_domain *d, const double *points, dk_index n, dk_index *embed,
                     double *w, dk_error *err);

/* Fails naming the first handle none of d's held vertices belongs to (its samples all
 * fell outside the domain, or on vertices nearer another handle's). */
dk_status bbw_check_held(const bbw_domain *d, const dk_bbw_handles *h, dk_error *err);

dk_status bbw_surface_domain(const dk_mesh *mesh, const dk_bbw_handles *h, bbw_domain *d,
                             dk_error *err);

/* `resolution`: grid cells along the longest side. *has_volume 0 (DK_OK, nothing built)
 * when the shape encloses no grid point. */
dk_status bbw_volume_domain(const dk_mesh *mesh, const dk_bbw_handles *h, int resolution,
                            bbw_domain *d, int *has_volume, dk_error *err);

#endif
