/* Shape matching's pieces (dk_shape_matching.h): the clusters (clusters.c), their rest data
 * for a goal shape (rest_shape.c), the goals of a configuration (goals.c), the integrators
 * (integrators.c) and the driver (shape_matching.c). Not installed. */
#ifndef DK_SM_INTERNAL_H
#define DK_SM_INTERNAL_H

#include "dk_constraints.h"
#include "dk_parallel.h"
#include "dk_shape_matching.h"

/* Clusters in CSR form, with the vertex -> membership map. Membership k is vertex
 * member_vertex[k] in the cluster whose range holds k. */
typedef struct sm_clusters {
    dk_index n_clusters;
    dk_index *start;         /* n_clusters + 1                                            */
    dk_index *member_vertex; /* start[n_clusters]                                         */
    double *member_share;    /* phi: the vertex's share of the cluster (clusters.c: a cube's
                                trilinear hat, normalised; a vertex's shares sum to 1)     */
    double *member_mass;     /* m_i phi                                                    */
    dk_index *vm_start;      /* n_vertices + 1: vertex v's memberships are               */
    dk_index *vm_index;      /* vm_index[vm_start[v] .. vm_start[v+1]-1]                 */
} sm_clusters;

/* Builds the clusters: the given ones (options->n_clusters > 0), one per connected part
 * (PARTS), or the automatic cubes of edge cluster_size overlapping by half, each
 * split into its connected pieces (a mesh with faces); a piece of fewer than 4 vertices is
 * dropped, and a vertex left in no cluster gets one of the nearest 8 vertices of its part
 * by edges. `kinematic` (n_vertices, 1 = not simulated) only decides what must be covered. */
dk_status sm_clusters_build(const dk_mesh *mesh, const dk_shape_matching_options *options,
                            const double *masses, const unsigned char *kinematic,
                            sm_clusters *out, dk_error *err);
void sm_clusters_free(sm_clusters *c);

/* The rest data of every cluster for a goal shape: mass centre, the offsets q (3 per
 * membership; 9 for QUADRATIC: q~), and the regularised inverse (A_qq + L)^-1 (3x3 or 9x9
 * per cluster) with its regulariser L (the diagonal, 3 or 9 per cluster). */
typedef struct sm_rest {
    int dim;          /* 3 (RIGID, LINEAR) or 9 (QUADRATIC)                               */
    double *q;        /* dim per membership                                               */
    double *inv;      /* dim x dim per cluster                                            */
    double *lambda;   /* dim per cluster                                                  */
    double *mass;     /* per cluster: sum of its members' masses                          */
    double *half;     /* dim 3: 9 per cluster, (A_qq + L)^(1/2)                           */
    double *ihalf;    /* dim 3: 9 per cluster, (A_qq + L)^(-1/2)                          */
    double *log_det;  /* dim 3: per cluster, log det (A_qq + L)^(1/2)                     */
    double *cm;       /* 3 per cluster: the goal shape's mass centre                      */
    unsigned char *plastic; /* per cluster: 1 when q is S_p (y - cm), not y - cm           */
    const double *shape; /* the goal shape (n_vertices x 3) the data were computed from:
                            the linear modes read y - cm from it rather than q (set by the
                            driver; its content stays that shape while the data are used)  */
} sm_rest;

dk_status sm_rest_alloc(const sm_clusters *c, int dim, sm_rest *r, dk_error *err);
void sm_rest_free(sm_rest *r);

/* Fills `r` for the goal shape `y` (n_vertices x 3) and the clusters' plastic states `sp`
 * (9 per cluster, row-major; NULL: none), whose frame is the bind rest's: `rest` (the bind's
 * positions) turns each into the goal shape's frame when `y` is not the rest. Clusters
 * [begin, end) only (so that passes can split them). */
void sm_rest_compute(const sm_clusters *c, const double *y, const double *rest,
                     const double *sp, sm_rest *r, dk_index begin, dk_index end);

/* Per-cluster scratch of a goal pass: the rotation and the linear fit (for plasticity). */
typedef struct sm_fit {
    double R[9];
    double A[9];
} sm_fit;

/* The goals of configuration x (n_vertices x 3) for clusters [begin, end), with the
 * per-vertex beta `beta` (n_vertices): per membership its cluster's goal into `member_goal`
 * (3 per membership), or, when `acc` is given, added to its vertex's row of acc (n_vertices
 * x 3; the caller zeroes it). `fits` (per cluster, may be NULL) receives R and the linear
 * fit. */
void sm_goals_clusters(const sm_clusters *c, const sm_rest *r, dk_shape_matching_mode mode,
                       const double *beta, const double *x, double *member_goal, double *acc,
                       sm_fit *fits, dk_index begin, dk_index end);

/* The blended goal (sum of share x goal) of each vertex in [begin, end) from the two
 * halves' sums acc0 + acc1 (the clusters split in two passes); a vertex in no cluster gets
 * its own position. */
void sm_goals_from_sums(const sm_clusters *c, const double *acc0, const double *acc1,
                        const double *x, double *goals, dk_index begin, dk_index end);

/* The blended goal of each vertex in [begin, end) from member_goal; a vertex in no cluster gets
 * its own position. */
void sm_goals_vertices(const sm_clusters *c, const double *member_goal, const double *x,
                       double *goals, dk_index begin, dk_index end);

/* The rotation Q from cluster cl at the bind's `rest` to it in the goal shape y: the closest
 * rotation to their cross-covariance, about their mass centres (y's: r->cm, with r->mass). */
void sm_rest_to_goal(const sm_clusters *c, const sm_rest *r, const double *y,
                     const double *rest, dk_index cl, double Q[9]);

/* Where a plastic state changes: updates sp (9 per cluster, in the bind rest's frame) from
 * the fits (in the frame of the goal shape y) for a step of h seconds, turning each step back
 * by the rotation Q from the cluster at the bind's `rest` to it in y: S_p <- Q^T F Q S_p.
 * Returns how many clusters changed (their rest data must be recomputed). */
dk_index sm_plastic_update(const sm_clusters *c, const sm_rest *r, const sm_fit *fits, double h,
                           const dk_shape_matching_dynamics *dyn, const double *y,
                           const double *rest, double *sp, unsigned char *changed);

/* The attachments of the free vertices (attachments.c): a (n; 0 for kinematic vertices) the
 * strength, and the kinematic vertices whose move off the input moves each one's attached
 * place: vertex[start[v] .. start[v+1]-1] with shares summing to 1 (none for a vertex with
 * no attachment). */
typedef struct sm_attach {
    double *a;
    dk_index *start; /* n + 1                                                               */
    dk_index *vertex;
    double *share;
} sm_attach;

/* Builds the attachments for the kinematic set `kin` (n; 1 = kinematic) of the constraints
 * `con` (its roles name each kinematic vertex's group: a handle, or the input), the falloff
 * (0: half the depth of the simulated region, at most `cap`; sm_attach_cap) and the painted
 * map (n, or NULL). */
dk_status sm_attach_build(const dk_mesh *mesh, const dk_constraints *con,
                          const unsigned char *kin, double falloff, double cap,
                          const double *attach_map, sm_attach *out, dk_error *err);

/* The automatic falloff's cap for these options: half the automatic cubes' edge, or no cap
 * (INFINITY) for whole parts and given clusters. */
double sm_attach_cap(const dk_mesh *mesh, const dk_shape_matching_options *options);
void sm_attach_free(sm_attach *a);

/* The linear mode's volume-preserving fit (volume_fit.c). sm_volume_metric: of the
 * symmetric positive definite m = A_qq + L (3 x 3), m^(1/2), m^(-1/2) and log det m^(1/2).
 * sm_volume_fit: A (3 x 3, the best linear fit A*, det > 0) replaced by the best fit with
 * det 1 in m's metric, argmin_{det A = 1} |(A - A*) m^(1/2)|_F; 0 (A unchanged) where m
 * is singular or A* M^(1/2) is not positive definite in its stretch (det A* <= 0). */
void sm_volume_metric(const double m[9], double half[9], double ihalf[9], double *log_det);
int sm_volume_fit(double A[9], const double half[9], const double ihalf[9], double log_det);

/* What one substep needs (integrators.c). */
typedef struct sm_step {
    dk_index n;
    const unsigned char *kinematic; /* n                                                    */
    const double *k;                /* n: stiffness per unit mass, alpha_i / h_frame^2      */
    const double *d;                /* n: damping rates                                     */
    const double *u;                /* n x 3: the input's velocity over the frame, which the
                                       damping is relative to (0 for a still input)         */
    double gravity[3];
    double h;                       /* the substep                                          */
} sm_step;

/* One substep of the chosen integrator for the free vertices, x and v in place. `goals_at`
 * evaluates the goals of a configuration (goals.c through the driver), with the kinematic
 * vertices placed at fraction `tau` of the substep by `place`; `ctx` is theirs. Scratch:
 * `work` holds 6 n x 3 doubles (RK4's stages). */
typedef void (*sm_goals_fn)(void *ctx, const double *x, double *goals);
typedef void (*sm_place_fn)(void *ctx, double *x, double *v, double tau);
void sm_integrate(const sm_step *st, dk_shape_matching_integrator integrator, double *x,
                  double *v, double *goals, sm_goals_fn goals_at, sm_place_fn place, void *ctx,
                  double *work);

#endif
