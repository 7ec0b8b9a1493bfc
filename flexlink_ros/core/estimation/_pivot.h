/*
 * Partial pivoting's two row operations, shared by the LUs of the linear step (_radau_step.c)
 * and of the nonlinear step (_nonlinear_step.c); include after Python.h and math.h.
 */
#ifndef FLEXLINK_PIVOT_H
#define FLEXLINK_PIVOT_H

/* Row of the largest |a[i][col]| for i in [from, n), the first of equals (n x n, row-major). */
static inline Py_ssize_t pivot_row_of(const double *a, Py_ssize_t n, Py_ssize_t col,
                                      Py_ssize_t from, double *best_out)
{
    Py_ssize_t p = from;
    double best = fabs(a[from * n + col]);
    for (Py_ssize_t i = from + 1; i < n; i++) {
        const double v = fabs(a[i * n + col]);
        p = v > best ? i : p;
        best = v > best ? v : best;
    }
    *best_out = best;
    return p;
}

/* Swap rows i and k of a (rows of n; nothing when i == k). */
static inline void swap_rows(double *a, Py_ssize_t n, Py_ssize_t i, Py_ssize_t k)
{
    if (i == k)
        return;
    double *restrict x = a + i * n, *restrict y = a + k * n;
    for (Py_ssize_t j = 0; j < n; j++) {
        const double t = x[j];
        x[j] = y[j];
        y[j] = t;
    }
}

#endif
