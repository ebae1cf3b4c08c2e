/* Plain 3-vector / 3x3-matrix helpers, mirroring impedance_cosim/physics/linalg3.py operation for
 * operation (same evaluation order), so native and Python FMUs compute the same numbers.
 * Matrices are row-major double[9]. */
#ifndef LINALG3_H
#define LINALG3_H

/* out = m v */
static inline void matvec(const double m[9], const double v[3], double out[3])
{
    const double x = v[0], y = v[1], z = v[2];
    out[0] = m[0] * x + m[1] * y + m[2] * z;
    out[1] = m[3] * x + m[4] * y + m[5] * z;
    out[2] = m[6] * x + m[7] * y + m[8] * z;
}

/* out = m^T v */
static inline void matTvec(const double m[9], const double v[3], double out[3])
{
    const double x = v[0], y = v[1], z = v[2];
    out[0] = m[0] * x + m[3] * y + m[6] * z;
    out[1] = m[1] * x + m[4] * y + m[7] * z;
    out[2] = m[2] * x + m[5] * y + m[8] * z;
}

/* Solve m x = v by Cramer's rule (as linalg3.solve); returns 0, or 1 when det(m) == 0. */
static inline int solve3(const double m[9], const double v[3], double out[3])
{
    const double a = m[0], b = m[1], c = m[2], d = m[3], e = m[4], f = m[5];
    const double g = m[6], h = m[7], i = m[8];
    const double x = v[0], y = v[1], z = v[2];
    const double c00 = e * i - f * h;
    const double c01 = f * g - d * i;
    const double c02 = d * h - e * g;
    const double det = a * c00 + b * c01 + c * c02;
    if (det == 0.0) {
        return 1;
    }
    {
        const double inv_det = 1.0 / det;
        out[0] = (c00 * x + (c * h - b * i) * y + (b * f - c * e) * z) * inv_det;
        out[1] = (c01 * x + (a * i - c * g) * y + (c * d - a * f) * z) * inv_det;
        out[2] = (c02 * x + (b * g - a * h) * y + (a * e - b * d) * z) * inv_det;
    }
    return 0;
}

#endif
