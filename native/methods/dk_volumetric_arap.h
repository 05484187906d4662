/* DeformKit: volumetric As-Rigid-As-Possible deformation, the slides' volume-based
 * deformation: the solid a closed surface bounds, tetrahedralized, deformed as rigidly as
 * possible per tetrahedron. See docs/methods/volumetric_arap.md.
 *
 * Bind. (1) The tetrahedra: TetGen meshes the interior (dk_tetrahedralize_surface: the
 * surface is the tetrahedra's boundary and its vertices are their first points, bit for bit;
 * `quality` bounds the radius-edge ratio, `max_volume` the size; without a size bound the
 * tetrahedra grow towards the middle, so the interior adds fewer points than the surface
 * has). (2) ARAP on them (dk_arap_bind_tetrahedra): with F_t = D_s D_m^-1 each tetrahedron's
 * deformation gradient,
 *     E(x) = sum_t s_t vol_t |F_t - R_t|^2 + sum_{soft handle vertices v} k_v |x_v - t_v|^2,
 * R_t the rotation closest to F_t, s_t the mean stiffness of its corners (the slides' ARAP
 * energy sum_j lambda_j |F_j - R_j|^2 with lambda_j = s_j vol_j), minimised over the surface
 * and interior points together by ARAP's solvers (Newton by default, as for the surface).
 * (3) The interior's harmonic extension: the linear elements' Laplacian on the interior
 * points, factored, which moves the interior with a given surface (an input pose, a given
 * start, energy()). The handles, fixed vertices and region of interest are the surface's
 * vertex groups, as for every vertex-group method: interior points are free (inside the
 * region of interest when there is one), interior stiffness spreads inwards from the surface
 * (each interior point the mean of its neighbours nearer the surface).
 *
 * Only a closed manifold surface bounds a volume. Each connected part of the mesh whose every
 * edge is in two triangles is tetrahedralized (one TetGen run for all of them); the other
 * parts -- with a hole or a non-manifold edge -- bound none and deform as surfaces
 * (ARAP's spoke cells, in the same solve), and when TetGen refuses the closed parts
 * (crossing or degenerate triangles) the whole mesh does: dk_volumetric_arap_note says which,
 * stats count the tetrahedra. (Ours: the embedding lattice for scans with holes is
 * not built; docs/methods/volumetric_arap.md.) With embed (below) a coarse volume carries a
 * closed surface instead, and open parts are refused.
 *
 * Solve: the surface's positions (n_vertices x 3); the interior is the object's (stats
 * n_interior_points). request.input_positions: the pose to edit, the interior moved with it
 * by the harmonic extension; request.start_positions (DK_START_GIVEN) likewise.
 * energy(positions): E of the volume whose surface is `positions` and whose interior is the
 * last solve's moved by the harmonic extension of the surface's difference from that solve's
 * result (before any solve: the rest's interior), so that the energy of a solve's result is
 * the energy it reported.
 */
#ifndef DK_VOLUMETRIC_ARAP_H
#define DK_VOLUMETRIC_ARAP_H

#include "dk_arap.h"
#include "dk_constraints.h"
#include "dk_mesh.h"
#include "dk_method.h"
#include "dk_progress.h"
#include "dk_status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct dk_volumetric_arap_options {
    double quality;      /**< the tetrahedra's largest radius-edge ratio (TetGen's q): 0
                              (none: no interior point, slivers allowed) or in [1.1, 10];
                              default 1.5                                                 */
    double max_volume;   /**< the largest tetrahedron's volume, in the mesh's units cubed:
                              0 (none, the default) or > 0, at least 1 / 5e7 of the
                              mesh's bounding box (TetGen's refinement cannot be stopped) */
    int max_iterations;  /**< >= 1, default 1000 (dk_arap_options)                        */
    double tolerance;    /**< >= 0, default 1e-6 (dk_arap_options)                        */
    dk_arap_acceleration acceleration; /**< default DK_ARAP_ACCEL_NEWTON                  */
    int cg_iterations;   /**< NEWTON: 1..100, default 12 (dk_arap_options)                */
    int levels;          /**< the multi-scale solve (docs/methods/volumetric_arap.md,
                              "Multi-scale"): 1 the volume alone; 2 a coarse level: the
                              surface simplified to 1/16 of its vertices (each vertex's role
                              kept), tetrahedralized and bound as a VolumetricARAP of its
                              own, attached to the solver (dk_arap_attach_coarse_level: cold
                              starts solved there first and prolonged; no corrections of
                              the Newton steps, which did not pay on volumes); 0 (the
                              default): automatic, the level from 10,000 points on. No
                              level where a part bounds no volume, or TetGen refuses the
                              coarse surface (a mesh with no volume at all is ARAP's, its
                              own levels automatic unless this is 1). The answer is a
                              minimum of the volume's energy by the same test; a big edit
                              with several (a half turn) can end in another one. 0..2   */
    int embed;           /**< how the volume carries the surface (docs/methods/
                              volumetric_arap.md, "Big meshes"): 1 the surface is the
                              tetrahedra's boundary (its vertices their first points);
                              2 a coarse volume carries it: the surface simplified to
                              1/16 of its vertices (each vertex's role kept), that
                              tetrahedralized and bound as a VolumetricARAP of its own
                              (`levels` passed on), and every vertex moved by the coarse
                              volume's move at its barycentric coordinates in the coarse
                              tetrahedra (extrapolated outside them), handles and fixed
                              vertices then exactly where they must be: the minimum of the
                              coarse volume's energy, not the surface's own volume's;
                              every part must bound a volume; 0 (the default):
                              automatic, 2 from 250,000 vertices on where every part
                              bounds a volume (the full volume would pass 3 GB). 0..2   */
    dk_phase_progress_fn progress; /**< bind progress: the phases tetrahedralize, interior
                                        (the harmonic extension's factor), then ARAP's
                                        (dk_arap_options.progress), coarse (the level),
                                        "done" at 1 (embedded: "coarse volume", the
                                        coarse volume's bind inside it); non-zero
                                        cancels. TetGen's meshing cannot be interrupted  */
    void *progress_user;
} dk_volumetric_arap_options;

typedef struct dk_volumetric_arap dk_volumetric_arap;

/** Fills the defaults above. */
void dk_volumetric_arap_default_options(dk_volumetric_arap_options *options);

/** Binds: tetrahedralizes the surface's interior, builds the harmonic extension and binds
 *  ARAP on the tetrahedra with `constraints` (vertex groups of the surface). The mesh must
 *  outlive the object. */
dk_status dk_volumetric_arap_bind(const dk_mesh *mesh, const dk_constraint_desc *constraints,
                                  const dk_volumetric_arap_options *options,
                                  dk_volumetric_arap **out, dk_error *err);

/** New constraints; the tetrahedra and the extension are kept (dk_arap_rebind). With a
 *  coarse volume carrying the surface (embed) the coarse volume is made again for them (the
 *  simplification keeps the groups' roles); on failure the old binding stays. */
dk_status dk_volumetric_arap_rebind(dk_volumetric_arap *va,
                                    const dk_constraint_desc *constraints, dk_error *err);

/** The progress callback of the following rebinds (dk_arap_set_progress; NULL: none). */
void dk_volumetric_arap_set_progress(dk_volumetric_arap *va, dk_phase_progress_fn progress,
                                     void *user);

/** Solves (dk_method.h; starts, previews, slices as dk_arap_solve): `positions` gets the
 *  surface, n_vertices x 3. */
dk_status dk_volumetric_arap_solve(dk_volumetric_arap *va, const dk_solve_request *request,
                                   double *positions, dk_solve_info *info, dk_error *err);

/** E (above) of the surface `positions` (n_vertices x 3) into `energy`. Uses the object's
 *  scratch (not re-entrant: one call on an object at a time, as for every verb) and ARAP's
 *  energy, which allocates an n_points x 3 copy. */
dk_status dk_volumetric_arap_energy(const dk_volumetric_arap *va, const double *positions,
                                    double *energy, dk_error *err);

/** The contract's counters (dk_method.h); zeros for NULL. */
void dk_volumetric_arap_stats(const dk_volumetric_arap *va, dk_method_stats *stats);

/** The tetrahedra: their points (surface first) and count. */
typedef struct dk_volumetric_arap_counters {
    dk_index n_points;          /**< surface vertices and interior points                 */
    dk_index n_interior_points; /**< points TetGen added inside                           */
    dk_index n_tetrahedra;
} dk_volumetric_arap_counters;

/** The ARAP object on the tetrahedra, for its solve-time settings (dk_arap_set_tolerance,
 *  dk_arap_set_cg_iterations); owned by `va`. NULL for NULL. */
dk_arap *dk_volumetric_arap_solver(dk_volumetric_arap *va);

/** dk_arap_response_basis of the solver on the tetrahedra, the mesh's vertices' rows:
 *  `out` n_vertices x (4 n_handles) (dk_arap_get_counters(dk_volumetric_arap_solver(va))
 *  .basis_columns columns). DK_ERR_INVALID_ARGUMENT when the basis was not built.
 *  Allocates an n_points x columns scratch. */
dk_status dk_volumetric_arap_response_basis(const dk_volumetric_arap *va, double *out,
                                            dk_error *err);

/** Why a part (or the whole mesh) deforms as a surface: "" when every part bounds a volume;
 *  valid while the object lives. */
const char *dk_volumetric_arap_note(const dk_volumetric_arap *va);

/** Fills `counters` (zeros for NULL). */
void dk_volumetric_arap_get_counters(const dk_volumetric_arap *va,
                                     dk_volumetric_arap_counters *counters);

/** The current tetrahedral mesh, for display and checks: `points` (n_points x 3: the last
 *  solve's result, or the rest before any solve) and `tetrahedra` (n_tetrahedra x 4,
 *  positively oriented at rest); either may be NULL. */
void dk_volumetric_arap_tetrahedra(const dk_volumetric_arap *va, double *points,
                                   dk_index *tetrahedra);

/** 1 when a coarse volume carries the surface (the option embed, chosen or automatic),
 *  else 0 (also for NULL). */
int dk_volumetric_arap_embedded(const dk_volumetric_arap *va);

/** Frees; NULL allowed. */
void dk_volumetric_arap_free(dk_volumetric_arap *va);

/** State (dk_method_ops): ARAP's on the tetrahedra and the last solved volume. */
size_t dk_volumetric_arap_state_size(const dk_volumetric_arap *va);
dk_status dk_volumetric_arap_save_state(const dk_volumetric_arap *va, void *state, size_t size,
                                        dk_error *err);
dk_status dk_volumetric_arap_restore_state(dk_volumetric_arap *va, const void *state,
                                           size_t size, dk_error *err);

/** The bytes a bind needs at its peak (dk_method_estimate_memory). */
dk_status dk_volumetric_arap_estimate_memory(const dk_mesh *mesh,
                                             const dk_volumetric_arap_options *options,
                                             uint64_t *bytes, dk_error *err);

/** The method's table (dk_method.h); options are a dk_volumetric_arap_options. */
extern const dk_method_ops dk_volumetric_arap_ops;

#ifdef __cplusplus
}
#endif
#endif
