/* DeformKit skinning, internal: a bone's motion as the solve uses it (skinning.c) and the
 * dual quaternions of dual quaternion skinning (dual_quaternion.c). */
#ifndef DK_SKINNING_INTERNAL_H
#define DK_SKINNING_INTERNAL_H

/* One bone's motion M = T B^-1 = [A | t], and for dual quaternion skinning its polar parts
 * A = R S and the unit dual quaternion (real part r, dual part d; w, x, y, z) of [R | t]. */
typedef struct skin_bone {
    double A[9], t[3];
    double S[9];
    double r[4], d[4];
} skin_bone;


/* The dual quaternion (r, d) of the rigid motion x -> R x + t: r from R, d = (0, t) r / 2. */
void skin_dq_from_rigid(const double R[9], const double t[3], double r[4], double d[4]);

/* Applies the dual quaternion (r, d), r not necessarily of unit length (a blend): divided by
 * |r| (the dual part by the same), then x -> R(r) x + 2 vec(d conj(r)). Writes out (3);
 * r of length 0 leaves x. */
void skin_dq_apply(const double r[4], const double d[4], const double x[3], double out[3]);

#endif
