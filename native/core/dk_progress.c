/* DeformKit: progress reports in named phases (dk_progress.h). */
#include "dk_progress.h"

void dk_progress_init(dk_progress *p, dk_phase_progress_fn fn, void *user,
                      const dk_progress_phase *phases, int n_phases, const char *who)
{
    p->fn = fn;
    p->user = user;
    p->phases = phases;
    p->n_phases = n_phases;
    p->phase = -1;
    p->total = 0.0;
    for (int k = 0; k < n_phases; k++)
        p->total += phases[k].weight > 0.0 ? phases[k].weight : 0.0;
    p->start = p->span = 0.0;
    p->last = 0.0;
    p->ticks = 0;
    p->who = who ? who : "bind";
}

static const char *phase_name(const dk_progress *p)
{
    return p->phase >= 0 && p->phase < p->n_phases ? p->phases[p->phase].name : "start";
}

/* Asks the callback at `fraction` (kept non-decreasing and in [0, 1]). */
static dk_status report(dk_progress *p, double fraction, dk_error *err)
{
    p->ticks = 0;
    if (!p->fn)
        return DK_OK;
    if (!(fraction >= p->last)) /* NaN too */
        fraction = p->last;
    if (fraction > 1.0)
        fraction = 1.0;
    p->last = fraction;
    if (p->fn(p->user, phase_name(p), fraction))
        return dk_error_set(err, DK_ERR_CANCELLED, "%s: cancelled in phase %s", p->who,
                            phase_name(p));
    return DK_OK;
}

dk_status dk_progress_begin(dk_progress *p, int k, dk_error *err)
{
    if (!p)
        return DK_OK;
    if (k < 0 || k >= p->n_phases || k <= p->phase)
        return dk_error_set(err, DK_ERR_INTERNAL, "%s: progress phase %d after %d of %d",
                            p->who, k, p->phase, p->n_phases);
    double before = 0.0;
    for (int i = 0; i < k; i++)
        before += p->phases[i].weight > 0.0 ? p->phases[i].weight : 0.0;
    const double w = p->phases[k].weight > 0.0 ? p->phases[k].weight : 0.0;
    p->phase = k;
    p->start = p->total > 0.0 ? before / p->total : 0.0;
    p->span = p->total > 0.0 ? w / p->total : 0.0;
    return report(p, p->start, err);
}

dk_status dk_progress_part(dk_progress *p, double part, dk_error *err)
{
    if (!p)
        return DK_OK;
    if (!(part >= 0.0))
        part = 0.0;
    if (part > 1.0)
        part = 1.0;
    return report(p, p->start + p->span * part, err);
}

dk_status dk_progress_tick(dk_progress *p, double done, double total, dk_error *err)
{
    if (!p || !p->fn || ++p->ticks < DK_PROGRESS_TICK)
        return DK_OK;
    return dk_progress_part(p, total > 0.0 ? done / total : 0.0, err);
}

void dk_progress_done(dk_progress *p)
{
    if (!p || !p->fn)
        return;
    p->last = 1.0;
    p->ticks = 0;
    (void)p->fn(p->user, "done", 1.0); /* the work is whole: a stop changes nothing */
}
