/* LAPACK's dense symmetric eigensolvers with work arrays allocated here (dk_lapack.h). */
#include "dk_lapack.h"

#include <lapacke.h>
#include <stdlib.h>

int dk_lapack_dsyev(char jobz, int n, double *a, double *w)
{
    double query = 0.0;
    lapack_int info = LAPACKE_dsyev_work(LAPACK_COL_MAJOR, jobz, 'U', n, a, n > 0 ? n : 1, w,
                                         &query, -1);
    if (info != 0)
        return (int)info;
    const lapack_int lwork = (lapack_int)query > 1 ? (lapack_int)query : 1;
    double *work = malloc((size_t)lwork * sizeof *work);
    if (!work)
        return LAPACK_WORK_MEMORY_ERROR;
    info = LAPACKE_dsyev_work(LAPACK_COL_MAJOR, jobz, 'U', n, a, n > 0 ? n : 1, w, work, lwork);
    free(work);
    return (int)info;
}

int dk_lapack_dsyevd(char jobz, int n, double *a, double *w)
{
    double query = 0.0;
    lapack_int iquery = 0;
    lapack_int info = LAPACKE_dsyevd_work(LAPACK_COL_MAJOR, jobz, 'U', n, a, n > 0 ? n : 1, w,
                                          &query, -1, &iquery, -1);
    if (info != 0)
        return (int)info;
    const lapack_int lwork = (lapack_int)query > 1 ? (lapack_int)query : 1;
    const lapack_int liwork = iquery > 1 ? iquery : 1;
    double *work = malloc((size_t)lwork * sizeof *work);
    lapack_int *iwork = malloc((size_t)liwork * sizeof *iwork);
    if (!work || !iwork) {
        free(work);
        free(iwork);
        return LAPACK_WORK_MEMORY_ERROR;
    }
    info = LAPACKE_dsyevd_work(LAPACK_COL_MAJOR, jobz, 'U', n, a, n > 0 ? n : 1, w, work, lwork,
                               iwork, liwork);
    free(work);
    free(iwork);
    return (int)info;
}

int dk_lapack_dstev(char jobz, int n, double *d, double *e, double *z, int ldz)
{
    /* LAPACK dstev: work of max(1, 2n - 2) when vectors are wanted, unreferenced otherwise */
    const size_t lwork = n > 1 ? 2 * (size_t)n - 2 : 1;
    double *work = malloc(lwork * sizeof *work);
    if (!work)
        return LAPACK_WORK_MEMORY_ERROR;
    const lapack_int info = LAPACKE_dstev_work(LAPACK_COL_MAJOR, jobz, n, d, e, z, ldz, work);
    free(work);
    return (int)info;
}
