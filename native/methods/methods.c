/* DeformKit: the registry of methods (dk_method.h) and the request checks they share. */
#include "dk_method.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "dk_arap.h"
#include "dk_cage.h"
#include "dk_eigen.h"
#include "dk_embedded.h"
#include "dk_falloff.h"
#include "dk_fundamental.h"
#include "dk_laplacian_edit.h"
#include "dk_lattice.h"
#include "dk_shape_interpolation.h"
#include "dk_shape_matching.h"
#include "dk_shepard.h"
#include "dk_skinning.h"
#include "dk_volumetric_arap.h"

/* Adding a method: its table here, in the order the Python module lists its classes. */
static const dk_method_ops *const registry[] = {&dk_arap_ops, &dk_laplacian_edit_ops,
                                                &dk_falloff_ops, &dk_embedded_ops, &dk_eigen_ops,
                                                &dk_fundamental_ops, &dk_lattice_ops, &dk_cage_ops,
                                                &dk_shepard_ops, &dk_skinning_ops,
                                                &dk_shape_matching_ops,
                                                &dk_shape_interpolation_ops,
                                                &dk_volumetric_arap_ops, NULL};

const dk_method_ops *const *dk_methods(void)
{
    return registry;
}

const dk_method_ops *dk_method_find(const char *name)
{
    if (!name)
        return NULL;
    for (const dk_method_ops *const *m = registry; *m; m++)
        if (strcmp((*m)->name, name) == 0)
            return *m;
    return NULL;
}

static dk_status request_check(const dk_solve_request *rq, const char *who, dk_error *err);

dk_status dk_solve_request_check(const dk_solve_request *rq, const char *who, dk_error *err)
{
    const dk_status st = request_check(rq, who, err);
    if (st == DK_OK && rq->input_positions)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: this method does not edit an input (input_positions): it "
                            "deforms its bind's rest", who);
    return st;
}

dk_status dk_solve_request_check_input(const dk_solve_request *rq, dk_index n_vertices,
                                       const char *who, dk_error *err)
{
    dk_status st = request_check(rq, who, err);
    if (st != DK_OK || !rq->input_positions)
        return st;
    st = dk_check_positions(rq->input_positions, n_vertices, err);
    return st == DK_OK ? st : dk_error_prefix(err, "%s: input_positions", who);
}

static dk_status request_check(const dk_solve_request *rq, const char *who, dk_error *err)
{
    if (!rq)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: the request is NULL", who);
    if (!rq->targets)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: targets must not be NULL", who);
    if (rq->target_kind != DK_TARGETS_POSITIONS && rq->target_kind != DK_TARGETS_TRANSFORMS)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: target kind %d is neither positions (0) nor transforms (1)",
                            who, (int)rq->target_kind);
    if (rq->start != DK_START_COLD && rq->start != DK_START_WARM &&
        rq->start != DK_START_RESUME && rq->start != DK_START_GIVEN)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: start %d is not cold (0), warm (1), resume (2) or given (3)",
                            who, (int)rq->start);
    if ((rq->start == DK_START_GIVEN) != (rq->start_positions != NULL))
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            rq->start_positions ? "%s: start_positions are given but the start "
                                                  "is not DK_START_GIVEN"
                                                : "%s: start DK_START_GIVEN needs "
                                                  "start_positions",
                            who);
    if (rq->max_iterations < 0)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT,
                            "%s: max_iterations is %d, must be >= 0 (0: the bound option)",
                            who, rq->max_iterations);
    if (rq->preview != 0 && rq->preview != 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: preview must be 0 or 1", who);
    if (rq->skip_energy != 0 && rq->skip_energy != 1)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: skip_energy must be 0 or 1",
                            who);
    return DK_OK;
}

dk_status dk_solve_result_check(const double *positions, dk_index n_vertices, double energy,
                                int check_energy, const char *who, dk_error *err)
{
    double largest = 0.0;
    for (int64_t i = 0; i < 3 * (int64_t)n_vertices; i++) {
        const double x = positions[i];
        if (!isfinite(x))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "%s: the result is not finite (vertex %lld coordinate %c is "
                                "%g): the constraints or the mesh are too large or too "
                                "degenerate for double precision; nothing was returned",
                                who, (long long)(i / 3), "xyz"[i % 3], x);
        if (fabs(x) > largest)
            largest = fabs(x);
    }
    if (check_energy && !isfinite(energy))
        return dk_error_set(err, DK_ERR_NONFINITE,
                            "%s: the energy is %g (overflow: the largest coordinate of the "
                            "result is %g); the positions are finite: solve without the "
                            "energy (energy=False, skip_energy) to get them",
                            who, energy, largest);
    return DK_OK;
}

dk_status dk_start_positions_check(const double *start_positions, dk_index n_vertices,
                                   const char *who, dk_error *err)
{
    for (int64_t i = 0; i < 3 * (int64_t)n_vertices; i++)
        if (!isfinite(start_positions[i]))
            return dk_error_set(err, DK_ERR_NONFINITE,
                                "%s: start_positions are not finite (vertex %lld coordinate "
                                "%c is %g)",
                                who, (long long)(i / 3), "xyz"[i % 3], start_positions[i]);
    return DK_OK;
}

dk_status dk_energy_result_check(double energy, const char *who, dk_error *err)
{
    if (isfinite(energy))
        return DK_OK;
    return dk_error_set(err, DK_ERR_NONFINITE,
                        "%s: the energy is %g (overflow: the positions are too large for "
                        "double precision)", who, energy);
}

void dk_constraints_held_stats(const dk_constraints *c, const dk_index *to_caller,
                               dk_method_stats *stats)
{
    stats->n_held = c ? c->n_held : 0;
    stats->n_held_components = c ? c->n_held_components : 0;
    stats->first_held = c ? c->first_held : -1;
    if (c && to_caller && c->n_held > 0) {
        dk_index first = -1;
        for (dk_index v = 0; v < c->n_vertices; v++)
            if (c->held[v] && (first < 0 || to_caller[v] < first))
                first = to_caller[v];
        stats->first_held = first;
    }
}

double dk_displacement_energy(const double *positions, const double *base, dk_index n)
{
    double e = 0.0;
    for (size_t k = 0; k < 3 * (size_t)n; k++) {
        const double d = positions[k] - base[k];
        e += d * d;
    }
    return e;
}

dk_status dk_displacement_energy_result(const double *positions, const double *base,
                                        dk_index n, const char *who, double *energy,
                                        dk_error *err)
{
    if (!positions || !base || !energy)
        return dk_error_set(err, DK_ERR_INVALID_ARGUMENT, "%s: arguments must not be NULL", who);
    const double e = dk_displacement_energy(positions, base, n);
    const dk_status st = dk_energy_result_check(e, who, err);
    if (st == DK_OK)
        *energy = e;
    return st;
}

dk_status dk_direct_solve_finish(const double *positions, const double *base, dk_index n,
                                 const dk_solve_request *rq, const char *who,
                                 dk_solve_info *info, dk_error *err)
{
    const double e = rq->skip_energy ? NAN : dk_displacement_energy(positions, base, n);
    const dk_status st = dk_solve_result_check(positions, n, e, !rq->skip_energy, who, err);
    if (st == DK_OK && info) {
        info->energy = e;
        info->iterations = 1;
        info->converged = 1;
    }
    return st;
}
