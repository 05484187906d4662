/* DeformKit: the constrained-system steps that the methods solving sparse systems share
 * (ARAP, Laplacian editing, and the methods to come): whether every part of the mesh that
 * has unknowns is anchored, and factoring a system whose pattern a rebind may keep.
 *
 * A method says which vertices are unknowns and how strongly a soft constraint pulls each
 * (that differs per method: ARAP eliminates hard handles and keeps soft ones as penalised
 * unknowns; least-squares Laplacian editing keeps every vertex of the region unknown) and
 * assembles its own matrix; these functions number the unknowns and the target rows, check
 * that every part of the mesh with unknowns is anchored, and factor with one policy, the
 * same for all. */
#ifndef DK_CSYS_H
#define DK_CSYS_H

#include "dk_cholesky.h"
#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_parallel.h"
#include "dk_progress.h"
#include "dk_sparse.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Which rows of the constraints' expanded targets each vertex takes: target_of[v] = k for
 *  the k-th handle vertex (in handle order), -1 for every other vertex (n_vertices). */
void dk_csys_target_rows(const dk_constraints *c, dk_index *target_of);

/** A method's choice for vertex v: returns 1 when v is an unknown of its system, 0 when it
 *  is eliminated, and writes the weight of v's soft constraint (0 for none) to *soft. */
typedef int (*dk_csys_classify_fn)(const void *ctx, dk_index v, double *soft);

/** Numbers the unknowns in vertex order: unknown_index[v] = u or -1 (n entries), and, when
 *  not NULL, unknowns[u] = v (room for n) and soft[v] = the classify weight (n). Returns
 *  the number of unknowns; *n_soft (may be NULL) gets how many vertices have a soft
 *  weight > 0. */
dk_index dk_csys_number_unknowns(dk_index n, dk_csys_classify_fn classify, const void *ctx,
                                 dk_index *unknown_index, dk_index *unknowns, double *soft,
                                 dk_index *n_soft);

/** Whether internal vertex v pins its connected component (an eliminated vertex, a soft
 *  constraint row, or whatever else makes the method's system definite there). */
typedef int (*dk_csys_anchor_fn)(const void *ctx, dk_index v);

/** Refuses a system that is singular because a connected component holds unknowns but no
 *  anchor: DK_ERR_DEGENERATE, "<who>: connected component C (the component of vertex V)
 *  has free vertices but no handle or fixed vertex, so its position is undetermined;
 *  <hint>", naming the caller's first such vertex V and its component C in the caller's
 *  mesh.
 *  mesh            the method's (internal) mesh, with its component ids
 *  unknown_index   n_vertices: >= 0 for an unknown vertex of `mesh`
 *  anchored, ctx   the method's anchor test
 *  iperm           n_vertices: the caller's vertex v is internal vertex iperm[v] (NULL: the
 *                  same numbering)
 *  caller_mesh     the caller's mesh, for the component id in the message (NULL: mesh) */
dk_status dk_csys_check_components(const dk_mesh *mesh, const dk_index *unknown_index,
                                   dk_csys_anchor_fn anchored, const void *ctx,
                                   const dk_index *iperm, const dk_mesh *caller_mesh,
                                   const char *who, const char *hint, dk_error *err);

/** When a factorization that reuses an analysis is redone. */
typedef enum dk_csys_refactor {
    DK_CSYS_REFACTOR_ALWAYS = 0,    /**< whenever the system is rebuilt                    */
    DK_CSYS_REFACTOR_IF_CHANGED = 1 /**< only when its values differ from the old ones     */
} dk_csys_refactor;

/** The counters a method reports (dk_method_stats). */
typedef struct dk_csys_counts {
    int analysis_count, factorization_count;
} dk_csys_counts;

/** Factors `a` into *chol. When `old_chol` holds a factor of `old_a` and `same_pattern` is
 *  non-zero (the caller knows the patterns agree: the same unknown set), its symbolic
 *  analysis is taken over (*old_chol becomes NULL) and refactored per `policy`; if that
 *  numeric factorization fails, the analysis goes back to *old_chol, refactored with
 *  old_a's values, so that the object keeps working with its previous system (or, should
 *  even that fail, *old_chol is freed and NULL). Otherwise a new analysis, which runs its
 *  substitutions on `team` (may be NULL). Counts into `counts`. On failure *chol is NULL
 *  and the status and message are the analysis' or factorization's (DK_ERR_NOT_POSITIVE_
 *  DEFINITE, ...), for the caller to prefix.
 *  `progress` (may be NULL): the caller's reporter, whose phase `analyze_phase` is the
 *  symbolic analysis and `analyze_phase + 1` the numeric factorization. Each is entered
 *  (dk_progress_begin) before it starts -- the analysis is skipped when it is taken over --
 *  and a request to stop there returns DK_ERR_CANCELLED with *chol NULL and *old_chol as it
 *  was. Neither CHOLMOD call can be interrupted: the longest stretch without a question is
 *  the numeric factorization (docs/reliability.md gives it at 692k vertices). */
dk_status dk_csys_factor(const dk_sparse *a, dk_cholesky **chol, dk_cholesky **old_chol,
                         const dk_sparse *old_a, int same_pattern, dk_csys_refactor policy,
                         dk_team *team, dk_csys_counts *counts, dk_progress *progress,
                         int analyze_phase, dk_error *err);

/** 1 when a and b have the same dimensions and pattern (column starts and row indices). */
int dk_csys_same_pattern(const dk_sparse *a, const dk_sparse *b);

#ifdef __cplusplus
}
#endif
#endif
