/*
 * The validity indicator of one estimate: the kernel shared by _nonlinearity.c (its Python
 * form, indicator()) and _radau_step.c (the streaming update's compiled path). The per-sample
 * form of flexlink_ros/core/estimation/nonlinearity.py (NonlinearityIndicator.__call__, its
 * Python twin and reference; a test compares them).
 *
 *   context  float64: grid, r, links, modes, speeds, zeta, speed_max, cells per radian,
 *            1 / (w^2 step of the reference grid), rest speed, then omega (speeds x modes) and
 *            shares (speeds x modes x links) of the reference modes (INDICATOR_* below).
 *   table    float64 (grid, 4, links, 7 r + 3): the cells' spline coefficients of the rows of
 *            Eq. (1) of core/reduction/nonlinearity_tables.py over P_cr.
 *   state    float64 (2 r): q, then q'.
 *
 * Static functions only: each module that includes it compiles its own copy (the same code,
 * the same flags, so the same doubles).
 */
#ifndef FLEXLINK_NONLINEARITY_H
#define FLEXLINK_NONLINEARITY_H

#include <math.h>
#include <stddef.h>

enum {
    INDICATOR_GRID, INDICATOR_SIZE, INDICATOR_LINKS, INDICATOR_MODES, INDICATOR_SPEEDS,
    INDICATOR_ZETA, INDICATOR_SPEED_MAX, INDICATOR_CELL_SCALE, INDICATOR_INVERSE_STEP2,
    INDICATOR_REST_SPEED, INDICATOR_HEADER
};
#define INDICATOR_MAX_LINKS 8
#define INDICATOR_TWO_PI 6.283185307179586

/*
 * N_e / P_cr of each link at cell k, position t (Eq. 1 of nonlinearity_tables.py): the cell's
 * cubic in t of each row, element by element, dotted with the extended state
 * x = (q, a q, w^2 q, q', w q', w^2 q', w^4 q', 1, a, w^2) in four partial sums (independent
 * chains that vectorise: a single running sum was most of the indicator's time).
 */
static void indicator_link_ratios(const double *cell, const double *state, ptrdiff_t r,
                                  int links, double t, double speed, double accel,
                                  double *ratios)
{
    const ptrdiff_t width = 7 * r + 3;
    const double w2 = speed * speed;
    const double scales[7] = {1.0, accel, w2, 1.0, speed, w2, w2 * w2};
    double x[width];
    for (int m = 0; m < 7; m++) {
        const double *part = state + (m < 3 ? 0 : r);
        for (ptrdiff_t j = 0; j < r; j++)
            x[m * r + j] = scales[m] * part[j];
    }
    x[7 * r] = 1.0;
    x[7 * r + 1] = accel;
    x[7 * r + 2] = w2;
    for (int l = 0; l < links; l++) {
        const double *r0 = cell + l * width, *r1 = r0 + links * width,
                     *r2 = r1 + links * width, *r3 = r2 + links * width;
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
        ptrdiff_t j = 0;
        for (; j + 4 <= width; j += 4) {
            s0 += x[j] * (r0[j] + t * (r1[j] + t * (r2[j] + t * r3[j])));
            s1 += x[j + 1] * (r0[j + 1] + t * (r1[j + 1] + t * (r2[j + 1] + t * r3[j + 1])));
            s2 += x[j + 2] * (r0[j + 2] + t * (r1[j + 2] + t * (r2[j + 2] + t * r3[j + 2])));
            s3 += x[j + 3] * (r0[j + 3] + t * (r1[j + 3] + t * (r2[j + 3] + t * r3[j + 3])));
        }
        for (; j < width; j++)
            s0 += x[j] * (r0[j] + t * (r1[j] + t * (r2[j] + t * r3[j])));
        ratios[l] = (s0 + s1) + (s2 + s3);
    }
}

/* max over the reference modes of |Delta omega| / sqrt(d^2 + (zeta omega)^2) (Eq. 3). */
static double indicator_detuning(const double *context, const double *ratios, double speed)
{
    const int modes = (int)context[INDICATOR_MODES], links = (int)context[INDICATOR_LINKS];
    const int speeds = (int)context[INDICATOR_SPEEDS];
    const double zeta = context[INDICATOR_ZETA], rate = fabs(speed);
    const double *omega = context + INDICATOR_HEADER;
    const double *share = omega + speeds * modes;
    const double position = speed * speed * context[INDICATOR_INVERSE_STEP2];
    int i = (int)position;
    if (i > speeds - 2)
        i = speeds - 2;
    double f = position - i;
    if (f > 1.0)
        f = 1.0;
    double worst = 0.0;
    for (int j = 0; j < modes; j++) {
        const double o0 = omega[i * modes + j], o1 = omega[(i + 1) * modes + j];
        const double om = o0 + f * (o1 - o0);
        double total = 0.0;
        for (int l = 0; l < links; l++) {
            const double s0 = share[(i * modes + j) * links + l];
            const double s1 = share[((i + 1) * modes + j) * links + l];
            total += (s0 + f * (s1 - s0)) * ratios[l];
        }
        double harmonic = om;
        if (rate > context[INDICATOR_REST_SPEED])     /* nearest k >= 1, ties to even */
            harmonic = fmax(nearbyint(om / rate), 1.0) * rate;
        const double value = fabs(0.5 * om * total) / hypot(om - harmonic, zeta * om);
        if (value > worst)
            worst = value;
    }
    return worst;
}

/* Values the context needs (header and reference modes), or -1 if its sizes are bad. */
static ptrdiff_t indicator_context_size(const double *context, ptrdiff_t length)
{
    if (length < INDICATOR_HEADER)
        return -1;
    const double links = context[INDICATOR_LINKS], modes = context[INDICATOR_MODES];
    const double speeds = context[INDICATOR_SPEEDS];
    if (!(links >= 1 && links <= INDICATOR_MAX_LINKS && modes >= 1 && modes < 1e6
          && speeds >= 2 && speeds < 1e6 && context[INDICATOR_GRID] >= 1
          && context[INDICATOR_GRID] < 1e9 && context[INDICATOR_SIZE] >= 1
          && context[INDICATOR_SIZE] < 1e6))
        return -1;
    return INDICATOR_HEADER + (ptrdiff_t)speeds * (ptrdiff_t)modes * (1 + (ptrdiff_t)links);
}

/* Values the table needs for the context's grid, size and links. */
static ptrdiff_t indicator_table_size(const double *context)
{
    const ptrdiff_t r = (ptrdiff_t)context[INDICATOR_SIZE];
    return (ptrdiff_t)context[INDICATOR_GRID] * 4 * (ptrdiff_t)context[INDICATOR_LINKS]
           * (7 * r + 3);
}

/* The indicator of one sample (context and table checked); NaN for a non-finite input. */
static double indicator_value(const double *context, const double *table, const double *state,
                              double angle, double speed, double accel)
{
    if (!(isfinite(speed) && isfinite(accel) && isfinite(angle)))
        return NAN;
    const ptrdiff_t grid = (ptrdiff_t)context[INDICATOR_GRID];
    const ptrdiff_t r = (ptrdiff_t)context[INDICATOR_SIZE];
    const int links = (int)context[INDICATOR_LINKS];
    double x = fmod(angle, INDICATOR_TWO_PI);
    if (x < 0.0)
        x += INDICATOR_TWO_PI;
    x *= context[INDICATOR_CELL_SCALE];
    ptrdiff_t k = (ptrdiff_t)x;
    if (k > grid - 1)
        k = grid - 1;
    const double speed_max = context[INDICATOR_SPEED_MAX];
    speed = speed > speed_max ? speed_max : (speed < -speed_max ? -speed_max : speed);
    double ratios[INDICATOR_MAX_LINKS];
    indicator_link_ratios(table + k * 4 * links * (7 * r + 3), state, r, links, x - k, speed,
                          accel, ratios);
    return indicator_detuning(context, ratios, speed);
}

#endif
