/*
 * The streaming estimator's per-sample step in C: the same arithmetic as
 * the numpy step, NumpyStep._step (core/estimation/step.py), without its ~30 numpy calls.
 *
 * One 2-stage Radau IIA step of the reduced model M q'' + C q' + K q = f over h:
 *   - M, C, K, f at the first stage (crank state at c1 h, interpolated between samples)
 *     and at the sample, from the node tables of the cubic spline (Hermite weights =
 *     monomial * h00, h10, h01, h11 on nodes k and k + 1);
 *   - the step matrix and the operator on (q, v) from the 8 x 8 coefficient matrix
 *     G(h) = sum_p h^p g[p] (slot 0 = the sample, slot 1 = stage 1, see tables._StepTables);
 *   - the 2 r x 2 r system solved by LU with partial pivoting, z = (q, v) += dz;
 *   - the record: linear outputs, and with a model of order 2 their second-order part
 *     (the factored quadratic form of core/reduction/second_order_tables.py).
 * A sample whose step is split into sub-steps (MAX_SUBSTEP_NS) is advanced here too,
 * with the crank state linear between the samples, as NumpyStep._sub_steps does.
 * Batched rows (advance) and the streaming update both enter the step through step_sample.
 * A long batch (the offline replay's) records its rows in a thread of its own beside the
 * steps (RecordWorker): half of a row's arithmetic is its record.
 *
 * Also here: the crank-rate filter (CrankRateFilter.update), the joint criteria, and Update,
 * the whole StreamingEstimator.update of an ordinary sample in one call (gate, filter, step,
 * record, criteria, bound, validity indicator of _nonlinearity.h, the Sample), with the
 * Python path (core/estimation/compiled_update.py) taking every other sample.
 *
 * No numpy headers: arrays come through the buffer protocol (C-contiguous float64).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#if defined(__unix__) || defined(__APPLE__)
#include <pthread.h>
#define RECORD_THREAD 1     /* advance's records in a thread of their own (RecordWorker) */
#endif

#include "_nonlinearity.h"      /* the validity indicator, for the streaming update */
#include "_pivot.h"

#define FIRST_MC 4      /* M and C start at monomial 1: weights[4:] */
#define GROUPS_C 4      /* C: monomials 1, w2, w, w4 (node rows V, S each) */
#define GROUPS_KF_MAX 4 /* K, f: monomials a, 1, w2; and w with stiffness damping (kf_groups) */
#define ROWS_ALL 28     /* all seven monomials x 4 (powers of t, or Hermite weights) */
#define OUTPUTS 4       /* deflection channels (reduced.OUTPUT_NAMES) */
#define JOINT_WIDTH 20  /* reactions (4 x 2), their rates (4 x 2), squared RMS (4) */
#define RECORD_SIZE (2 * OUTPUTS + JOINT_WIDTH)
#define POWERS 5        /* h^-2 .. h^2 */
#define ROW_FIELDS 6    /* h, count, angle, speed, accel, advance */
#define RELEASE_GIL_ROWS 64
#define SO_SCALARS 22   /* second order: cos, sin of 3 link angles, kappa 4 x 4 */
#define SO_TRIG 6       /* kappa's first scalar */
#define SO_FORMS 4      /* bending sums: crank, coupler, lever, coupler's half */
#define LIFT_BUFFERS 5  /* the soft basis's lift: phi, dphi, residual, lifted, history */

static const double TWO_PI = 6.283185307179586;
static const double PI = 3.141592653589793;     /* math.pi */

typedef struct {
    Py_ssize_t r, cells, mass_groups, kf_groups, out_rows, joint_rows;
    /* the soft basis (soft_tables.py): the step's r is p; the record's is rr, the lift
       q = Phi eta + residual, q' = Phi eta' + w Phi' eta from power-form cell tables, and
       [K | f] in float32 (kf32). rr == r, lift NULL: none. */
    Py_ssize_t rr;
    const float *lift_phi, *lift_dphi, *lift_residual;    /* float32 node tables */
    double *lifted;     /* [q, q', 1] of the reduced model (2 rr + 1) */
    double *history;    /* stage 1 by interpolation in time, or NULL: [count, h, X_n, X_n-1] */
    double *frame;      /* scratch: Phi, Phi' (rr x p each) */
    const float *mass, *damping;    /* float32, node tables: see tables._StepTables */
    const double *kf, *out, *joint, *g0;
    const float *kf32;  /* the soft basis's [K | f] node table (float32; kf is NULL then) */
    double cells_per_radian, c1;
    /* scratch */
    double *blocks;     /* [slot][m] r x r, m = M, C, K; slot 0 sample, 1 stage 1 */
    double *loads;      /* [slot] r */
    double *products;   /* [slot][m][l] r: X_{slot,m} z_l */
    double *matrix;     /* 2r x 2r */
    double *rhs;        /* 2r */
    double *operator;   /* outputs x (r + 1): [O | corr] of the record */
    double weights[ROWS_ALL];   /* power form: the record's per-cell tables */
    double hermite[ROWS_ALL];   /* Hermite form: the node tables */
    /* second-order outputs (core/reduction/second_order_tables.py); so_terms 0: order 1 */
    Py_ssize_t so_rows, so_slots, so_gathers, so_terms;
    const double *so_scalars, *so_v, *so_gather_coef, *so_form_value;
    const int *so_gather, *so_form;     /* (slot, row, scalar or -1), (form, slot, slot) */
    double *so_y, *so_z;                /* scratch: rows of V q, the links' (v, phi) */
} Step;

/* x86-64 with GCC: AVX2/FMA clones of the step and of the kernels it calls (the table
   combination and the LU are not inlined into the step's clone), chosen at load time (ifunc). */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define STEP_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define STEP_CLONES
#endif

/*
 * sum_j a[j] b[j] with four independent partial sums: a single running sum is a chain of
 * dependent additions (4 cycles each) that C may not reorder without -ffast-math; four
 * chains run in parallel and vectorise. (Round-off differs from numpy's order, not more.)
 */
static inline double dot(const double *restrict a, const double *restrict b, Py_ssize_t n)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    Py_ssize_t j = 0;
    for (; j + 4 <= n; j += 4) {
        s0 += a[j] * b[j];
        s1 += a[j + 1] * b[j + 1];
        s2 += a[j + 2] * b[j + 2];
        s3 += a[j + 3] * b[j + 3];
    }
    for (; j < n; j++)
        s0 += a[j] * b[j];
    return (s0 + s1) + (s2 + s3);
}

/* Row and Hermite weights at (angle, w, a) and the cell: NumpyStep.evaluate. */
static Py_ssize_t evaluate(const Step *s, double angle, double w, double a, double *weights,
                           double *hermite)
{
    double x = angle * s->cells_per_radian;
    Py_ssize_t k = (Py_ssize_t)x;
    if (k >= s->cells)
        k = s->cells - 1;
    if (k < 0)
        k = 0;
    double t = x - (double)k, t2 = t * t, t3 = t2 * t;
    double w2 = w * w;
    double mono[7] = {a, 1.0, w2, w, w2 * w2, w * a, w2 * w};
    const double h01 = t2 * (3.0 - 2.0 * t);
    const double basis[4] = {1.0 - h01, t - 2.0 * t2 + t3, h01, t3 - t2};
    for (int m = 0; m < 7; m++) {
        weights[4 * m] = mono[m];
        weights[4 * m + 1] = mono[m] * t;
        weights[4 * m + 2] = mono[m] * t2;
        weights[4 * m + 3] = mono[m] * t3;
        for (int i = 0; i < 4; i++)
            hermite[4 * m + i] = mono[m] * basis[i];
    }
    return k;
}

#if defined(__GNUC__) && !defined(__clang__)
/* GCC 12 warns of an overflow at iteration 2^61 of combine's loops, which the row bounds
   (at most ROWS_ALL, checked when the tables are taken) exclude. */
#pragma GCC diagnostic ignored "-Waggressive-loop-optimizations"
#endif

/*
 * out[j] = sum_i weights[i] table[i * stride + j], i < rows, j < width: four rows (one
 * monomial's powers of t) per pass, so out is loaded and stored once per four products.
 */
STEP_CLONES static void combine(const double *weights, const double *table, Py_ssize_t rows,
                                Py_ssize_t stride, Py_ssize_t width, double *restrict out)
{
    memset(out, 0, (size_t)width * sizeof(double));
    Py_ssize_t i = 0;
    for (; i + 4 <= rows; i += 4) {
        const double w0 = weights[i], w1 = weights[i + 1], w2 = weights[i + 2],
                     w3 = weights[i + 3];
        if (w0 == 0.0 && w1 == 0.0 && w2 == 0.0 && w3 == 0.0)
            continue;
        const double *restrict r0 = table + i * stride, *restrict r1 = r0 + stride,
                     *restrict r2 = r1 + stride, *restrict r3 = r2 + stride;
        for (Py_ssize_t j = 0; j < width; j++)
            out[j] += w0 * r0[j] + w1 * r1[j] + w2 * r2[j] + w3 * r3[j];
    }
    for (; i < rows; i++) {
        const double wi = weights[i];
        const double *restrict row = table + i * stride;
        for (Py_ssize_t j = 0; j < width; j++)
            out[j] += wi * row[j];
    }
}

/*
 * out[j] = sum over monomial groups g of the Hermite weights [4 g .. 4 g + 3] times the rows
 * V, S of node `lo` (2 g, 2 g + 1) and V, S of node `hi`: the node tables' form of combine.
 */
#define DEFINE_COMBINE_NODES(name, type)                                                    \
    STEP_CLONES static void name(const double *weights, const type *lo, const type *hi,     \
                                 Py_ssize_t groups, Py_ssize_t stride, Py_ssize_t width,    \
                                 double *restrict out)                                      \
    {                                                                                       \
        memset(out, 0, (size_t)width * sizeof(double));                                     \
        for (Py_ssize_t g = 0; g < groups; g++) {                                           \
            const double w0 = weights[4 * g], w1 = weights[4 * g + 1],                      \
                         w2 = weights[4 * g + 2], w3 = weights[4 * g + 3];                  \
            if (w0 == 0.0 && w1 == 0.0 && w2 == 0.0 && w3 == 0.0)                           \
                continue;                                                                   \
            const type *restrict r0 = lo + 2 * g * stride, *restrict r1 = r0 + stride,      \
                       *restrict r2 = hi + 2 * g * stride, *restrict r3 = r2 + stride;      \
            for (Py_ssize_t j = 0; j < width; j++)                                          \
                out[j] += w0 * (double)r0[j] + w1 * (double)r1[j] + w2 * (double)r2[j]      \
                          + w3 * (double)r3[j];                                             \
        }                                                                                   \
    }

DEFINE_COMBINE_NODES(combine_nodes, double)
DEFINE_COMBINE_NODES(combine_nodes_f32, float)

/* M, C, K and f of the crank state into a slot (NumpyStep._load). */
static void load(Step *s, int slot, double angle, double w, double a)
{
    const Py_ssize_t r = s->r, r2 = r * r;
    const Py_ssize_t k = evaluate(s, angle, w, a, s->weights, s->hermite);
    const Py_ssize_t k1 = k + 1 < s->cells ? k + 1 : 0;
    double *blocks = s->blocks + (Py_ssize_t)slot * 3 * r2;
    const Py_ssize_t mass_node = 2 * s->mass_groups * r2, damping_node = 2 * GROUPS_C * r2;
    combine_nodes_f32(s->hermite + FIRST_MC, s->mass + k * mass_node, s->mass + k1 * mass_node,
                      s->mass_groups, r2, r2, blocks);
    combine_nodes_f32(s->hermite + FIRST_MC, s->damping + k * damping_node,
                      s->damping + k1 * damping_node, GROUPS_C, r2, r2, blocks + r2);
    /* [K | f] from the kf table (monomials a, 1, w2, and w with stiffness damping) */
    const Py_ssize_t kf_width = r2 + r, kf_node = 2 * s->kf_groups * kf_width;
    if (s->kf32 != NULL) {
        const float *lo = s->kf32 + k * kf_node, *hi = s->kf32 + k1 * kf_node;
        combine_nodes_f32(s->hermite, lo, hi, s->kf_groups, kf_width, r2, blocks + 2 * r2);
        combine_nodes_f32(s->hermite, lo + r2, hi + r2, s->kf_groups, kf_width, r,
                          s->loads + slot * r);
    }
    else {
        const double *lo = s->kf + k * kf_node, *hi = s->kf + k1 * kf_node;
        combine_nodes(s->hermite, lo, hi, s->kf_groups, kf_width, r2, blocks + 2 * r2);
        combine_nodes(s->hermite, lo + r2, hi + r2, s->kf_groups, kf_width, r,
                      s->loads + slot * r);
    }
}

/*
 * Add the second-order outputs of q at cell k (weights set) to out[0 .. OUTPUTS - 1]:
 * SecondOrderForms (second_order_tables.py) in the same steps, per sample.
 */
static void second_order(Step *s, Py_ssize_t k, const double *q, double *restrict out)
{
    const double *cell = s->so_scalars + k * 4 * SO_SCALARS;
    const double *w = s->weights + 4;       /* monomial 1: powers of t */
    double sc[SO_SCALARS], sums[SO_FORMS] = {0.0, 0.0, 0.0, 0.0};
    for (int j = 0; j < SO_SCALARS; j++)
        sc[j] = w[0] * cell[j] + w[1] * cell[SO_SCALARS + j] + w[2] * cell[2 * SO_SCALARS + j]
                + w[3] * cell[3 * SO_SCALARS + j];
    for (Py_ssize_t i = 0; i < s->so_rows; i++)
        s->so_y[i] = dot(s->so_v + i * s->rr, q, s->rr);
    memset(s->so_z, 0, (size_t)s->so_slots * sizeof(double));
    for (Py_ssize_t p = 0; p < s->so_gathers; p++) {
        const int *g = s->so_gather + 3 * p;
        const double trig = g[2] < 0 ? 1.0 : sc[g[2]];
        s->so_z[g[0]] += s->so_gather_coef[p] * trig * s->so_y[g[1]];
    }
    for (Py_ssize_t p = 0; p < s->so_terms; p++) {
        const int *f = s->so_form + 3 * p;
        sums[f[0]] += s->so_form_value[p] * s->so_z[f[1]] * s->so_z[f[2]];
    }
    for (int o = 0; o < OUTPUTS; o++) {
        double add = 0.0;
        for (int f = 0; f < SO_FORMS; f++)
            add += sc[SO_TRIG + SO_FORMS * o + f] * (0.5 * sums[f]);
        out[o] += add;
    }
}

/* The lifted state [q, q', 1] of the soft state z at the crank state prev into s->lifted
   (SoftLift.state); the weights of prev are set. Returns the cell. */
static Py_ssize_t lift(Step *s, const double *z, const double *prev)
{
    const Py_ssize_t p = s->r, rr = s->rr, width = rr * p;
    const Py_ssize_t k = evaluate(s, prev[0], prev[1], prev[2], s->weights, s->hermite);
    const Py_ssize_t k1 = k + 1 < s->cells ? k + 1 : 0;
    double *frame = s->frame, *first = s->frame + width, *q = s->lifted, *v = s->lifted + rr;
    /* float32 Hermite node tables: phi (a, 1, w2, w), dphi (1), residual (a, 1, w2) */
    combine_nodes_f32(s->hermite, s->lift_phi + k * 8 * width, s->lift_phi + k1 * 8 * width,
                      4, width, width, frame);
    combine_nodes_f32(s->hermite + 4, s->lift_dphi + k * 2 * width,
                      s->lift_dphi + k1 * 2 * width, 1, width, width, first);
    combine_nodes_f32(s->hermite, s->lift_residual + k * 6 * rr,
                      s->lift_residual + k1 * 6 * rr, 3, rr, rr, q);
    /* the residual's rate along the crank angle: d/dtheta of the Hermite weights */
    const double t = s->weights[5], slope = 6.0 * t * t - 6.0 * t;
    const double basis_rate[4] = {slope, 3.0 * t * t - 4.0 * t + 1.0, -slope, 3.0 * t * t - 2.0 * t};
    double rates[12];
    for (int m = 0; m < 3; m++)
        for (int i = 0; i < 4; i++)
            rates[4 * m + i] = s->weights[4 * m] * basis_rate[i] * s->cells_per_radian;
    combine_nodes_f32(rates, s->lift_residual + k * 6 * rr, s->lift_residual + k1 * 6 * rr, 3,
                      rr, rr, v);
    for (Py_ssize_t i = 0; i < rr; i++) {
        q[i] += dot(frame + i * p, z, p);
        v[i] = dot(frame + i * p, z + p, p) + prev[1] * (dot(first + i * p, z, p) + v[i]);
    }
    s->lifted[2 * rr] = 1.0;
    return k;
}

/* The record of the crank state prev at the state z (tables._StepTables.record); with the
   soft basis, of its lift (computed here, into s->lifted). */
static void record(Step *s, const double *z, const double *prev, double *restrict out)
{
    const Py_ssize_t r = s->rr, width = OUTPUTS * (r + 1);
    Py_ssize_t k;
    if (s->lift_phi == NULL) {
        k = evaluate(s, prev[0], prev[1], prev[2], s->weights, s->hermite);
    }
    else {
        k = lift(s, z, prev);
        z = s->lifted;
    }
    double *op = s->operator;
    combine(s->weights, s->out + k * s->out_rows * width, s->out_rows, width, width, op);
    for (int o = 0; o < OUTPUTS; o++) {
        const double *row = op + o * (r + 1);
        out[o] = dot(row, z, r) + row[r];
        out[OUTPUTS + o] = row[r];
    }
    if (s->so_terms > 0)
        second_order(s, k, z, out);
    combine(s->weights, s->joint + k * s->joint_rows * JOINT_WIDTH, s->joint_rows, JOINT_WIDTH,
            JOINT_WIDTH, out + 2 * OUTPUTS);
}

#define LU_PANEL 4

/*
 * Eliminate column k below the pivot inside the panel (columns k .. k + width, width 0..3,
 * a fixed count per loop: a variable inner count of at most 3 cost more in loop set-up than
 * in arithmetic) and find the next column's pivot in the same pass.
 */
#define ELIMINATE(WIDTH)                                                                   \
    for (Py_ssize_t i = k + 1; i < n; i++) {                                               \
        double *restrict row = a + i * n + k;                                              \
        const double l = row[0] * inv;                                                     \
        row[0] = l;                                                                        \
        if (WIDTH >= 1) {                                                                  \
            row[1] -= l * p1;                                                              \
            const double v = fabs(row[1]);                                                 \
            next = v > next_best ? i : next;                                               \
            next_best = v > next_best ? v : next_best;                                     \
        }                                                                                  \
        if (WIDTH >= 2)                                                                    \
            row[2] -= l * p2;                                                              \
        if (WIDTH >= 3)                                                                    \
            row[3] -= l * p3;                                                              \
    }

/*
 * Solve a x = b (n x n, row-major) in place by LU with partial pivoting; -1 if singular.
 * Blocked right-looking LU: panels of LU_PANEL columns factored unblocked, then one rank-4
 * update of the trailing rows (each trailing element is loaded and stored once per four
 * products: about 25 % faster than the unblocked LU at n = 52 here). b follows the swaps.
 * Inside a panel the next column's pivot is found in the elimination's pass over the rows
 * (the panel was half of the LU's time with a separate strided search: 9.1 -> 7.2 us here).
 */
STEP_CLONES static int solve(Py_ssize_t n, double *restrict a, double *restrict b)
{
    for (Py_ssize_t k0 = 0; k0 < n; k0 += LU_PANEL) {
        const Py_ssize_t k1 = n - k0 < LU_PANEL ? n : k0 + LU_PANEL;
        /* the panel (columns k0..k1-1): pivot, swap whole rows, eliminate in the panel */
        double best;
        Py_ssize_t p = pivot_row_of(a, n, k0, k0, &best);
        for (Py_ssize_t k = k0; k < k1; k++) {
            if (!(best > 0.0))
                return -1;
            if (p != k) {
                swap_rows(a, n, k, p);
                double t = b[k];
                b[k] = b[p];
                b[p] = t;
            }
            const double *restrict pivot_row = a + k * n;
            const double inv = 1.0 / pivot_row[k];
            const Py_ssize_t width = k1 - k - 1;
            const double p1 = width >= 1 ? pivot_row[k + 1] : 0.0,
                         p2 = width >= 2 ? pivot_row[k + 2] : 0.0,
                         p3 = width >= 3 ? pivot_row[k + 3] : 0.0;
            /* the next column's pivot among rows k + 1.. (its row k is this pivot's row) */
            Py_ssize_t next = k + 1;
            double next_best = -1.0;
            switch (width) {
            case 3: ELIMINATE(3) break;
            case 2: ELIMINATE(2) break;
            case 1: ELIMINATE(1) break;
            default: ELIMINATE(0)
            }
            p = next;
            best = next_best;
        }
        if (k1 >= n)
            break;
        /* the panel's rows right of it: the unit lower triangle of the panel applied */
        for (Py_ssize_t k = k0; k < k1; k++) {
            const double *restrict row_k = a + k * n;
            for (Py_ssize_t i = k + 1; i < k1; i++) {
                double *restrict row = a + i * n;
                const double l = row[k];
                for (Py_ssize_t j = k1; j < n; j++)
                    row[j] -= l * row_k[j];
            }
        }
        /* trailing rows: rank-4 update (k1 - k0 == 4 whenever trailing rows remain) */
        const double *restrict u0 = a + k0 * n, *restrict u1 = u0 + n, *restrict u2 = u1 + n,
                     *restrict u3 = u2 + n;
        for (Py_ssize_t i = k1; i < n; i++) {
            double *restrict row = a + i * n;
            const double l0 = row[k0], l1 = row[k0 + 1], l2 = row[k0 + 2], l3 = row[k0 + 3];
            for (Py_ssize_t j = k1; j < n; j++)
                row[j] -= l0 * u0[j] + l1 * u1[j] + l2 * u2[j] + l3 * u3[j];
        }
    }
    for (Py_ssize_t i = 1; i < n; i++)         /* L y = b, L unit lower */
        b[i] -= dot(a + i * n, b, i);
    for (Py_ssize_t i = n - 1; i >= 0; i--) {  /* U x = y */
        const double *row = a + i * n;
        b[i] = (b[i] - dot(row + i + 1, b + i + 1, n - i - 1)) / row[i];
    }
    return 0;
}

static double wrap_once(double angle)
{
    if (angle >= TWO_PI)
        angle -= TWO_PI;
    else if (angle < 0.0)
        angle += TWO_PI;
    return angle;
}

/* Python's float %: the result takes the sign of the divisor. */
static double python_mod(double x, double y)
{
    double mod = fmod(x, y);
    if (mod != 0.0) {
        if ((y < 0.0) != (mod < 0.0))
            mod += y;
    }
    else {
        mod = copysign(0.0, y);
    }
    return mod;
}

/* The history's length (the soft basis's interpolated stage 1), or 0. */
static Py_ssize_t history_size(const Step *s)
{
    return s->history == NULL ? 0 : 2 + 2 * (3 * s->r * s->r + s->r);
}

/* Slot 0's [M, C, K | f] into a history entry. */
static void history_copy(Step *s, double *entry)
{
    const Py_ssize_t r = s->r, r2 = r * r;
    memcpy(entry, s->blocks, (size_t)(3 * r2) * sizeof(double));
    memcpy(entry + 3 * r2, s->loads, (size_t)r * sizeof(double));
}

/*
 * Stage 1 (slot 1) and the sample (slot 0) of a step of h from prev to (angle, w, a): both
 * from the tables, or (with a history) only the sample, stage 1 by interpolation in time
 * through the last two samples' evaluations and the new one (quadratic; linear with one,
 * after the previous sample is evaluated on a fresh start): NumpyStep.load_stages.
 */
static void load_stages(Step *s, const double *prev, double h, double angle, double w, double a,
                        double advance)
{
    const double c1 = s->c1;
    if (s->history == NULL) {
        load(s, 1, wrap_once(prev[0] + c1 * advance), prev[1] + c1 * (w - prev[1]),
             prev[2] + c1 * (a - prev[2]));
        load(s, 0, angle, w, a);
        return;
    }
    const Py_ssize_t r = s->r, matrices = 3 * r * r, width = matrices + r;
    double *count = s->history, *last = s->history + 2, *before = last + width;
    if (*count < 1.0) {
        load(s, 0, prev[0], prev[1], prev[2]);
        history_copy(s, last);
        *count = 1.0;
    }
    load(s, 0, angle, w, a);
    double weights[3];  /* on X_n-1, X_n, X_n+1 at t_n + c1 h (Lagrange) */
    if (*count >= 2.0) {
        const double back = s->history[1], x = c1 * h;
        weights[0] = x * (x - h) / (back * (back + h));
        weights[1] = (x + back) * (h - x) / (back * h);
        weights[2] = (x + back) * x / ((h + back) * h);
    }
    else {
        weights[0] = 0.0;
        weights[1] = 1.0 - c1;
        weights[2] = c1;
    }
    double *stage = s->blocks + matrices, *stage_load = s->loads + r;
    for (Py_ssize_t j = 0; j < matrices; j++)
        stage[j] = weights[0] * before[j] + weights[1] * last[j] + weights[2] * s->blocks[j];
    for (Py_ssize_t j = 0; j < r; j++)
        stage_load[j] = weights[0] * before[matrices + j] + weights[1] * last[matrices + j]
                        + weights[2] * s->loads[j];
    memcpy(before, last, (size_t)width * sizeof(double));
    history_copy(s, last);
    s->history[1] = h;
    *count = *count >= 2.0 ? 2.0 : *count + 1.0;
}

/* One Radau IIA step of h to crank state (angle, w, a) from prev (NumpyStep._step). */
STEP_CLONES static int radau_step(Step *s, double *z, double *prev, double h, double angle, double w,
                      double a, double advance)
{
    const Py_ssize_t r = s->r, r2 = r * r, n = 2 * r;
    load_stages(s, prev, h, angle, w, a, advance);
    prev[0] = angle;
    prev[1] = w;
    prev[2] = a;

    const double inv = 1.0 / h;
    const double hp[POWERS] = {inv * inv, inv, 1.0, h, h * h};
    double g[64];
    for (int e = 0; e < 64; e++) {
        double sum = 0.0;
        for (int p = 0; p < POWERS; p++)
            sum += hp[p] * s->g0[p * 64 + e];
        g[e] = sum;
    }
    /* X_{slot,m} z_l for the operator blocks (l = 2, 3 act on q, v) with any coefficient. */
    for (int slot = 0; slot < 2; slot++)
        for (int m = 0; m < 3; m++)
            for (int l = 0; l < 2; l++) {
                int used = 0;
                for (int i = 0; i < 2; i++)
                    used |= g[(i * 4 + 2 + l) * 8 + slot * 4 + m] != 0.0;
                double *out = s->products + ((slot * 3 + m) * 2 + l) * r;
                if (!used)
                    continue;
                const double *X = s->blocks + (slot * 3 + m) * r2;
                const double *zl = z + l * r;
                for (Py_ssize_t row = 0; row < r; row++)
                    out[row] = dot(X + row * r, zl, r);
            }
    /* matrix[(i, row), (l, col)] = sum_{slot, m} g[i, l; slot, m] X_{slot,m}[row, col] */
    for (int i = 0; i < 2; i++) {
        /* loads: stage 1 (slot 1) for the first block row, the sample (slot 0) for the second */
        const double *f = s->loads + (i == 0 ? 1 : 0) * r;
        double *rhs = s->rhs + i * r;
        for (Py_ssize_t row = 0; row < r; row++)
            rhs[row] = f[row];
        for (int l = 0; l < 4; l++) {
            const double *gl = g + (i * 4 + l) * 8;
            /* the block's terms (M, C, K of one stage: three), summed in one pass */
            const double *terms[6];
            double coefficients[6];
            int count = 0;
            for (int slot = 0; slot < 2; slot++)
                for (int m = 0; m < 3; m++) {
                    const double coefficient = gl[slot * 4 + m];
                    if (coefficient == 0.0)
                        continue;
                    if (l < 2) {
                        terms[count] = s->blocks + (slot * 3 + m) * r2;
                        coefficients[count++] = coefficient;
                    }
                    else {
                        const double *y = s->products + ((slot * 3 + m) * 2 + (l - 2)) * r;
                        for (Py_ssize_t row = 0; row < r; row++)
                            rhs[row] += coefficient * y[row];
                    }
                }
            if (l >= 2)
                continue;
            for (Py_ssize_t row = 0; row < r; row++) {
                double *restrict out = s->matrix + (i * r + row) * n + l * r;
                if (count == 3) {
                    const double c0 = coefficients[0], c1 = coefficients[1],
                                 c2 = coefficients[2];
                    const double *restrict x0 = terms[0] + row * r, *restrict x1 = terms[1] + row * r,
                                           *restrict x2 = terms[2] + row * r;
                    for (Py_ssize_t col = 0; col < r; col++)
                        out[col] = c0 * x0[col] + c1 * x1[col] + c2 * x2[col];
                    continue;
                }
                memset(out, 0, (size_t)r * sizeof(double));
                for (int t = 0; t < count; t++) {
                    const double c = coefficients[t];
                    const double *restrict x = terms[t] + row * r;
                    for (Py_ssize_t col = 0; col < r; col++)
                        out[col] += c * x[col];
                }
            }
        }
    }
    if (solve(n, s->matrix, s->rhs) != 0)
        return -1;
    /* A non-finite increment (from a non-finite table or state) is refused like a singular
       matrix, so z keeps its last finite value. */
    for (Py_ssize_t j = 0; j < n; j++)
        if (!isfinite(s->rhs[j]))
            return -1;
    for (Py_ssize_t j = 0; j < n; j++)
        z[j] += s->rhs[j];
    return 0;
}

/* A C-contiguous buffer of `count` values (any if < 0) of format "d" or "f" (item size). */
static int get_typed_buffer(PyObject *object, Py_buffer *view, int writable, const char *name,
                            Py_ssize_t count, const char *format)
{
    const Py_ssize_t size = format[0] == 'f' || format[0] == 'i' ? 4 : 8;
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(object, view, flags) != 0)
        return -1;
    if (view->itemsize != size || view->format == NULL || strcmp(view->format, format) != 0) {
        PyErr_Format(PyExc_TypeError, "`%s` must hold %s", name,
                     format[0] == 'i' ? "int32" : size == 4 ? "float32" : "float64");
        PyBuffer_Release(view);
        return -1;
    }
    if (count >= 0 && view->len != count * size) {
        PyErr_Format(PyExc_ValueError, "`%s` has %zd values, expected %zd", name,
                     view->len / size, count);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static int get_buffer(PyObject *object, Py_buffer *view, int writable, const char *name,
                      Py_ssize_t count)
{
    return get_typed_buffer(object, view, writable, name, count, "d");
}

PyDoc_STRVAR(advance_doc,
"advance(mass, damping, kf, out, joint, g0, cells_per_radian, c1, z, prev, rows, states,\n"
"        records, second=None)\n"
"\n"
"Advance the modal state z = [q, v, 1] through the sample rows (h, sub-steps, angle,\n"
"speed, acceleration, advance; 6 values each), 2-stage Radau IIA, as\n"
"NumpyStep._step. Tables as _StepTables (C order; mass and damping float32, the\n"
"rest float64). prev (angle, speed,\n"
"acceleration of the last step) is updated; states (rows x 2 r, or empty) receives\n"
"z[:2 r] after each row; records (rows x 28, or 28 for the last row only) the sample's\n"
"record (native.RECORD_SIZE). second: None (order 1) or (values float64, index int32) of\n"
"SecondOrderForms.packed (second_order_tables.py); their second-order outputs are added\n"
"to the record's deflections.");

#define SO_BUFFERS 2

/* The second-order tables (values, index: SecondOrderForms.packed) into s, checked: every
   count matches the buffers and every index lies within its array; or -1. */
static int take_second(PyObject *second, Py_buffer *views, Step *s)
{
    const Py_ssize_t r = s->rr;
    PyObject *values_obj, *index_obj;
    if (second == NULL || second == Py_None)
        return 0;
    if (!PyArg_ParseTuple(second, "OO;`second` must be (values, index)", &values_obj,
                          &index_obj))
        return -1;
    if (get_buffer(values_obj, &views[0], 0, "second values", -1) != 0
        || get_typed_buffer(index_obj, &views[1], 0, "second index", -1, "i") != 0)
        return -1;
    const int *index = views[1].buf;
    const Py_ssize_t count = views[1].len / 4;
    int bad = count < 3 || index[0] < 0 || index[1] < 0 || index[2] < 0;
    if (!bad) {
        s->so_rows = index[0];
        s->so_gathers = index[1];
        s->so_terms = index[2];
        bad = count != 3 + 3 * (s->so_gathers + s->so_terms)
              || views[0].len / 8 != s->cells * 4 * SO_SCALARS + s->so_rows * r
                                     + s->so_gathers + s->so_terms;
    }
    const int *gather = index + 3, *form = gather + 3 * (bad ? 0 : s->so_gathers);
    s->so_slots = 0;
    for (Py_ssize_t p = 0; !bad && p < s->so_gathers; p++) {
        bad = gather[3 * p] < 0 || gather[3 * p + 1] < 0 || gather[3 * p + 1] >= s->so_rows
              || gather[3 * p + 2] < -1 || gather[3 * p + 2] >= SO_SCALARS;
        if (gather[3 * p] >= s->so_slots)
            s->so_slots = gather[3 * p] + 1;
    }
    for (Py_ssize_t p = 0; !bad && p < s->so_terms; p++)
        bad = form[3 * p] < 0 || form[3 * p] >= SO_FORMS || form[3 * p + 1] < 0
              || form[3 * p + 2] < 0 || form[3 * p + 1] >= s->so_slots
              || form[3 * p + 2] >= s->so_slots;
    if (bad) {
        s->so_rows = s->so_gathers = s->so_terms = s->so_slots = 0;
        PyErr_SetString(PyExc_ValueError, "`second` tables do not match the model size or "
                        "hold an index out of range");
        return -1;
    }
    const double *values = views[0].buf;
    s->so_scalars = values;
    s->so_v = values + s->cells * 4 * SO_SCALARS;
    s->so_gather_coef = s->so_v + s->so_rows * r;
    s->so_form_value = s->so_gather_coef + s->so_gathers;
    s->so_gather = gather;
    s->so_form = form;
    return 0;
}

/* The soft basis's lift (phi, dphi, residual, lifted: SoftLift.packed and the lifted state)
   into s, its sizes checked against the step's r = p and the grid; or -1. */
static int take_lift(PyObject *lift_tuple, Py_buffer *views, Step *s)
{
    PyObject *objects[LIFT_BUFFERS] = {NULL};
    if (!PyArg_ParseTuple(lift_tuple, "OOOO|O;`lift` must be (phi, dphi, residual, lifted[, "
                          "history])", &objects[0], &objects[1], &objects[2], &objects[3],
                          &objects[4]))
        return -1;
    if (get_buffer(objects[3], &views[3], 1, "lifted", -1) != 0)
        return -1;
    const Py_ssize_t rr = (views[3].len / 8 - 1) / 2, p = s->r;
    if (rr < 1 || views[3].len / 8 != 2 * rr + 1) {
        PyErr_SetString(PyExc_ValueError, "`lifted` must have 2 r + 1 values");
        return -1;
    }
    if (get_typed_buffer(objects[0], &views[0], 0, "phi", s->cells * 8 * rr * p, "f") != 0
        || get_typed_buffer(objects[1], &views[1], 0, "dphi", s->cells * 2 * rr * p, "f") != 0
        || get_typed_buffer(objects[2], &views[2], 0, "residual", s->cells * 6 * rr, "f") != 0)
        return -1;
    s->rr = rr;
    s->lift_phi = views[0].buf;
    s->lift_dphi = views[1].buf;
    s->lift_residual = views[2].buf;
    s->lifted = views[3].buf;
    if (objects[4] != NULL && objects[4] != Py_None) {
        if (get_buffer(objects[4], &views[4], 1, "history", 2 + 2 * (3 * p * p + p)) != 0)
            return -1;
        s->history = views[4].buf;
    }
    return 0;
}

/* Rows (row groups) per grid cell or node of a table (at most `most`), or -1 with an exception set. */
static Py_ssize_t rows_of(const Py_buffer *view, Py_ssize_t per_row, Py_ssize_t cells,
                          Py_ssize_t most, const char *name)
{
    Py_ssize_t values = view->len / view->itemsize, rows = values / (cells * per_row);
    if (rows < 1 || rows > most || rows * cells * per_row != values) {
        PyErr_Format(PyExc_ValueError, "`%s` does not match the model size and grid", name);
        return -1;
    }
    return rows;
}

/* The buffers a Step holds while it is open (step_open, step_close). */
enum {
    VIEW_MASS, VIEW_DAMPING, VIEW_KF, VIEW_OUT, VIEW_JOINT, VIEW_G0, VIEW_SECOND,
    VIEW_LIFT = VIEW_SECOND + SO_BUFFERS, STEP_VIEWS = VIEW_LIFT + LIFT_BUFFERS
};
#define STEP_TABLES 6   /* mass, damping, kf, out, joint, g0 */

/*
 * Open a step of a model of size r: its tables (mass, damping, kf, out, joint, g0; second
 * None or SecondOrderForms.packed; lift None or the soft basis's (phi, dphi, residual,
 * lifted[, history]): then r is p and out, joint, second are the reduced model's), checked
 * against r and each other, into s with its scratch; 0, or -1 with an exception set.
 * step_close releases it either way.
 */
static int step_open(Step *s, Py_ssize_t r, PyObject *const *tables, PyObject *second,
                     PyObject *lift, double cells_per_radian, double c1, Py_buffer *views)
{
    const Py_ssize_t r2 = r * r, n = 2 * r;
    const int soft = lift != NULL && lift != Py_None;
    memset(s, 0, sizeof(*s));
    if (get_typed_buffer(tables[VIEW_DAMPING], &views[VIEW_DAMPING], 0, "damping", -1, "f")
        != 0)
        return -1;
    const Py_ssize_t cells = views[VIEW_DAMPING].len / 4 / (2 * GROUPS_C * r2);
    if (cells < 1 || views[VIEW_DAMPING].len / 4 != cells * 2 * GROUPS_C * r2) {
        PyErr_SetString(PyExc_ValueError, "`damping` does not match the size of `z`");
        return -1;
    }
    s->r = s->rr = r;
    s->cells = cells;
    if (soft && take_lift(lift, views + VIEW_LIFT, s) != 0)
        return -1;
    const Py_ssize_t rr = s->rr;
    if (get_typed_buffer(tables[VIEW_MASS], &views[VIEW_MASS], 0, "mass", -1, "f") != 0
        || (s->mass_groups = rows_of(&views[VIEW_MASS], 2 * r2, cells, GROUPS_C, "mass")) < 0
        || get_typed_buffer(tables[VIEW_KF], &views[VIEW_KF], 0, "kf", -1, soft ? "f" : "d")
           != 0
        || (s->kf_groups = rows_of(&views[VIEW_KF], 2 * (r2 + r), cells, GROUPS_KF_MAX, "kf"))
           < 0
        || get_buffer(tables[VIEW_OUT], &views[VIEW_OUT], 0, "out", -1) != 0
        || (s->out_rows = rows_of(&views[VIEW_OUT], OUTPUTS * (rr + 1), cells, ROWS_ALL, "out"))
           < 0
        || get_buffer(tables[VIEW_JOINT], &views[VIEW_JOINT], 0, "joint", -1) != 0
        || (s->joint_rows = rows_of(&views[VIEW_JOINT], JOINT_WIDTH, cells, ROWS_ALL, "joint"))
           < 0
        || get_buffer(tables[VIEW_G0], &views[VIEW_G0], 0, "g0", POWERS * 64) != 0)
        return -1;
    s->r = r;
    s->cells = cells;
    s->mass = views[VIEW_MASS].buf;
    s->damping = views[VIEW_DAMPING].buf;
    s->kf = soft ? NULL : views[VIEW_KF].buf;
    s->kf32 = soft ? views[VIEW_KF].buf : NULL;
    s->out = views[VIEW_OUT].buf;
    s->joint = views[VIEW_JOINT].buf;
    s->g0 = views[VIEW_G0].buf;
    s->cells_per_radian = cells_per_radian;
    s->c1 = c1;
    if (take_second(second, views + VIEW_SECOND, s) != 0)
        return -1;
    s->blocks = malloc(sizeof(double) * (size_t)(6 * r2 + 2 * r + 12 * r + n * n + n
                                                 + OUTPUTS * (rr + 1) + s->so_rows
                                                 + s->so_slots + 1 + 2 * rr * r));
    if (s->blocks == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    s->loads = s->blocks + 6 * r2;
    s->products = s->loads + 2 * r;
    s->matrix = s->products + 12 * r;
    s->rhs = s->matrix + n * n;
    s->operator = s->rhs + n;
    s->so_y = s->operator + OUTPUTS * (rr + 1);
    s->so_z = s->so_y + s->so_rows;
    s->frame = s->so_z + s->so_slots + 1;
    return 0;
}

/* Free a step's scratch and release its buffers (those not taken are empty). */
static void step_close(Step *s, Py_buffer *views)
{
    free(s->blocks);
    s->blocks = NULL;
    for (int i = 0; i < STEP_VIEWS; i++)
        PyBuffer_Release(&views[i]);
}

enum { SAMPLE_DONE = 0, SAMPLE_FAILED = -1, SAMPLE_BAD_ROW = -2 };

/*
 * Advance z = [q, v, 1] from the crank state prev through one sample row (h, sub-steps,
 * angle, speed, accel, advance; ROW_FIELDS) and write its record (record_out NULL: none):
 * the row's sub-steps with the crank state linear between the samples (NumpyStep._sub_steps),
 * each one Radau IIA step. SAMPLE_DONE, SAMPLE_FAILED (singular or non-finite: z keeps the
 * sub-steps done) or SAMPLE_BAD_ROW. The one entry of the batched replay (advance) and of the
 * streaming update (Update.sample) into the step.
 */
static int step_sample(Step *s, double *z, double *prev, const double *row,
                       double *record_out)
{
    const double h = row[0], angle = row[2], w = row[3], a = row[4], step = row[5];
    const long splits = row[1] >= 1.0 && row[1] < 1e9 ? (long)row[1] : 0;
    if (!(h > 0.0) || splits < 1)
        return SAMPLE_BAD_ROW;
    const double sub_h = h / (double)splits, sub_step = step / (double)splits;
    const double angle0 = prev[0], w0 = prev[1], a0 = prev[2];
    for (long i = 1; i < splits; i++) {
        const double f = (double)i / (double)splits;
        if (radau_step(s, z, prev, sub_h, python_mod(angle0 + step * f, TWO_PI),
                       w0 + f * (w - w0), a0 + f * (a - a0), sub_step) != 0)
            return SAMPLE_FAILED;
    }
    if (radau_step(s, z, prev, sub_h, angle, w, a, sub_step) != 0)
        return SAMPLE_FAILED;
    if (record_out != NULL)
        record(s, z, prev, record_out);         /* with the soft basis: lifted first */
    return SAMPLE_DONE;
}

/* Step rows and record them in this thread (every_record 0: only the last row's record). */
static int advance_alone(Step *s, double *zv, double *pv, const double *row, Py_ssize_t count,
                         double *state_out, double *record_out, int every_record)
{
    const int soft = s->lift_phi != NULL;
    const Py_ssize_t width = 2 * s->rr;
    int outcome = SAMPLE_DONE;
    for (Py_ssize_t m = 0; m < count; m++, row += ROW_FIELDS) {
        double *record_m = every_record ? record_out + m * RECORD_SIZE
                                        : (m == count - 1 ? record_out : NULL);
        outcome = step_sample(s, zv, pv, row, record_m);
        if (outcome != SAMPLE_DONE)
            break;
        if (state_out == NULL)
            continue;
        if (soft && record_m == NULL)
            lift(s, zv, pv);        /* (a record lifted the state already) */
        memcpy(state_out + m * width, soft ? s->lifted : zv, (size_t)width * sizeof(double));
    }
    return outcome;
}

#ifdef RECORD_THREAD
/* Rows a batch must have for its records to go to a thread of their own, and rows stepped
   between two hand-overs to it (each takes a lock). */
#define RECORD_THREAD_ROWS 256
#define RECORD_HANDOVER_ROWS 16

/*
 * The records of a batch (advance) computed beside its steps: the record of a row (and, with
 * the soft basis, its lift) needs only the row's state and crank state, not the steps after
 * it, and is half of a row's arithmetic. The stepper leaves each row's state z (q, v: 2 r) at
 * the start of its row of `states`; this thread reads it there, writes the row's record and
 * its lifted state over it, with a Step of its own (the same tables, its own scratch): the
 * same functions, so the same doubles as one thread. Both run without the GIL.
 */
typedef struct {
    Step s;
    double *scratch;
    const double *rows;
    double *states, *records;
    int soft;
    pthread_mutex_t lock;
    pthread_cond_t more;
    Py_ssize_t stepped;     /* rows whose state is in `states` (under lock) */
    int finished;           /* no row will follow `stepped` (under lock) */
} RecordWorker;

/* The record (and lifted state) of row m of a batch from its state in `states`. */
static void worker_record(RecordWorker *w, Py_ssize_t m)
{
    Step *s = &w->s;
    const Py_ssize_t width = 2 * s->rr;
    const double *row = w->rows + m * ROW_FIELDS;
    const double prev[3] = {row[2], row[3], row[4]};    /* the crank state after the row */
    double *state = w->states + m * width;
    record(s, state, prev, w->records + m * RECORD_SIZE);
    if (w->soft)
        memcpy(state, s->lifted, (size_t)width * sizeof(double));
}

static void *worker_run(void *arg)
{
    RecordWorker *w = arg;
    Py_ssize_t m = 0;
    for (;;) {
        pthread_mutex_lock(&w->lock);
        while (m >= w->stepped && !w->finished)
            pthread_cond_wait(&w->more, &w->lock);
        const Py_ssize_t stepped = w->stepped;
        pthread_mutex_unlock(&w->lock);
        if (m >= stepped)
            return NULL;
        for (; m < stepped; m++)
            worker_record(w, m);
    }
}

/* Hand rows [0, stepped) over to the worker; `finished`: no more will come. */
static void worker_hand_over(RecordWorker *w, Py_ssize_t stepped, int finished)
{
    pthread_mutex_lock(&w->lock);
    w->stepped = stepped;
    w->finished = finished;
    pthread_cond_signal(&w->more);
    pthread_mutex_unlock(&w->lock);
}

/* Start a worker on a copy of the stepper's Step s (scratch of its own); 0, or -1 (none:
   the caller records the rows itself). */
static int worker_start(RecordWorker *w, pthread_t *thread, const Step *s, const double *rows,
                        double *states, double *records)
{
    const Py_ssize_t rr = s->rr;
    memset(w, 0, sizeof(*w));
    w->s = *s;
    /* record's and lift's scratch: operator, so_y, so_z, frame, lifted */
    w->scratch = malloc(sizeof(double) * (size_t)(OUTPUTS * (rr + 1) + s->so_rows + s->so_slots
                                                  + 1 + 2 * rr * s->r + 2 * rr + 1));
    if (w->scratch == NULL)
        return -1;
    w->s.operator = w->scratch;
    w->s.so_y = w->s.operator + OUTPUTS * (rr + 1);
    w->s.so_z = w->s.so_y + s->so_rows;
    w->s.frame = w->s.so_z + s->so_slots + 1;
    w->s.lifted = w->s.frame + 2 * rr * s->r;
    w->rows = rows;
    w->states = states;
    w->records = records;
    w->soft = s->lift_phi != NULL;
    if (pthread_mutex_init(&w->lock, NULL) != 0) {
        free(w->scratch);
        return -1;
    }
    if (pthread_cond_init(&w->more, NULL) != 0) {
        pthread_mutex_destroy(&w->lock);
        free(w->scratch);
        return -1;
    }
    if (pthread_create(thread, NULL, worker_run, w) != 0) {
        pthread_cond_destroy(&w->more);
        pthread_mutex_destroy(&w->lock);
        free(w->scratch);
        return -1;
    }
    return 0;
}

/* Step rows with a worker recording them; the outcome as step_sample's, `done` the rows
   stepped. With the soft basis the stepper's lifted state is the last row's, as one thread
   leaves it. */
static int advance_with_worker(Step *s, RecordWorker *w, double *zv, double *pv,
                               const double *rows, Py_ssize_t count, double *states,
                               Py_ssize_t *done)
{
    const Py_ssize_t width = 2 * s->rr, z_width = 2 * s->r;
    int outcome = SAMPLE_DONE;
    Py_ssize_t m = 0;
    for (; m < count; m++) {
        outcome = step_sample(s, zv, pv, rows + m * ROW_FIELDS, NULL);
        if (outcome != SAMPLE_DONE)
            break;
        memcpy(states + m * width, zv, (size_t)z_width * sizeof(double));
        if ((m + 1) % RECORD_HANDOVER_ROWS == 0)
            worker_hand_over(w, m + 1, 0);
    }
    *done = m;
    return outcome;
}

/* Wait for a worker's records of rows [0, done) and free it. */
static void worker_finish(RecordWorker *w, pthread_t thread, Step *s, Py_ssize_t done)
{
    worker_hand_over(w, done, 1);
    pthread_join(thread, NULL);
    if (w->soft && done > 0)
        memcpy(s->lifted, w->states + (done - 1) * 2 * s->rr,
               (size_t)(2 * s->rr) * sizeof(double));
    pthread_cond_destroy(&w->more);
    pthread_mutex_destroy(&w->lock);
    free(w->scratch);
}
#endif

static PyObject *advance(PyObject *module, PyObject *args)
{
    PyObject *objects[15] = {NULL};
    double cells_per_radian, c1;
    (void)module;
    if (!PyArg_ParseTuple(args, "OOOOOOddOOOOO|OO", &objects[0], &objects[1], &objects[2],
                          &objects[3], &objects[4], &objects[5], &cells_per_radian, &c1,
                          &objects[8], &objects[9], &objects[10], &objects[11], &objects[12],
                          &objects[13], &objects[14]))
        return NULL;
    Py_buffer views[STEP_VIEWS] = {{0}};
    Py_buffer z = {0}, prev = {0}, rows = {0}, states = {0}, records = {0};
    PyObject *result = NULL;
    Step s;
    memset(&s, 0, sizeof(s));
    if (get_buffer(objects[8], &z, 1, "z", -1) != 0)
        return NULL;
    const Py_ssize_t r = (z.len / 8 - 1) / 2;
    if (r < 1 || z.len / 8 != 2 * r + 1) {
        PyErr_SetString(PyExc_ValueError, "`z` must have 2 r + 1 values");
        goto done;
    }
    if (step_open(&s, r, objects, objects[13], objects[14], cells_per_radian, c1, views) != 0
        || get_buffer(objects[9], &prev, 1, "prev", 3) != 0
        || get_buffer(objects[10], &rows, 0, "rows", -1) != 0)
        goto done;
    const Py_ssize_t count = rows.len / 8 / ROW_FIELDS;
    if (rows.len / 8 != count * ROW_FIELDS) {
        PyErr_SetString(PyExc_ValueError, "`rows` must have 6 values per row");
        goto done;
    }
    if (get_buffer(objects[11], &states, 1, "states", -1) != 0
        || get_buffer(objects[12], &records, 1, "records", -1) != 0)
        goto done;
    const Py_ssize_t rr = s.rr;
    if (states.len != 0 && states.len / 8 != count * 2 * rr) {
        PyErr_SetString(PyExc_ValueError, "`states` must be empty or rows x 2 r");
        goto done;
    }
    const int every_record = records.len / 8 == count * RECORD_SIZE;
    if (!every_record && records.len / 8 != RECORD_SIZE) {
        PyErr_SetString(PyExc_ValueError, "`records` must be rows x 28 or 28");
        goto done;
    }
    double *zv = z.buf, *pv = prev.buf, *state_out = states.len ? states.buf : NULL;
    double *record_out = records.buf;
    const double *row = rows.buf;
    int outcome;
    /* Batches (replay) let other threads run; a single sample keeps the GIL: getting it back
       can wait for another thread's switch interval (5 ms), far longer than the step. */
    PyThreadState *released = count >= RELEASE_GIL_ROWS ? PyEval_SaveThread() : NULL;
#ifdef RECORD_THREAD
    RecordWorker worker;
    pthread_t worker_thread;
    if (every_record && state_out != NULL && count >= RECORD_THREAD_ROWS
        && worker_start(&worker, &worker_thread, &s, row, state_out, record_out) == 0) {
        Py_ssize_t done = 0;
        outcome = advance_with_worker(&s, &worker, zv, pv, row, count, state_out, &done);
        worker_finish(&worker, worker_thread, &s, done);
    }
    else
#endif
        outcome = advance_alone(&s, zv, pv, row, count, state_out, record_out, every_record);
    if (released != NULL)
        PyEval_RestoreThread(released);
    if (outcome != SAMPLE_DONE) {
        PyErr_SetString(PyExc_ValueError, outcome == SAMPLE_BAD_ROW
                        ? "a row has a non-positive step or no sub-steps"
                        : "singular or non-finite Radau step");
        goto done;
    }
    result = Py_NewRef(Py_None);
done:
    step_close(&s, views);
    PyBuffer_Release(&z);
    PyBuffer_Release(&prev);
    PyBuffer_Release(&rows);
    PyBuffer_Release(&states);
    PyBuffer_Release(&records);
    return result;
}

/* ---- crank-rate filter: CrankRateFilter.update (crank_filter.py), the same arithmetic - */

/* State layout (float64), mirrored by estimator.FILTER_STATE_* */
enum {
    F_STARTED, F_TIME, F_ANGLE, F_MODE, F_SPEED, F_ACCEL, F_ADVANCE, F_MEAN_DT, F_TC,
    F_MIN_SAMPLES, F_SPEED_FIT, F_ANGLE_FIT = F_SPEED_FIT + 9, FILTER_STATE = F_ANGLE_FIT + 9
};
enum { MODE_NONE = 0, MODE_SPEED = 1, MODE_ANGLE = 2 };
/* A fit: s0..s4, t0..t2, count (_ForgettingPolyFit, degree 2). */

/* The Python expressions' order, without fused multiply-adds, so the results are the same
   doubles as the Python filter's (the step's tolerance would allow less, replay's tests not). */
#if defined(__GNUC__) && !defined(__clang__)
#define EXACT_ARITHMETIC __attribute__((optimize("fp-contract=off")))
#else
#define EXACT_ARITHMETIC
#endif

/* _ForgettingPolyFit.add (degree 2) with _shift_quadratic_moments. */
EXACT_ARITHMETIC static void fit_add(double *fit, double shift, double forget, double dy,
                                     double value)
{
    if (fit[8] != 0.0) {
        const double d = -shift, f = forget;
        const double s0 = fit[0], s1 = fit[1], s2 = fit[2], s3 = fit[3], s4 = fit[4];
        const double t0 = fit[5] - dy * s0, t1 = fit[6] - dy * s1, t2 = fit[7] - dy * s2;
        const double d2 = d * d;
        fit[0] = f * s0;
        fit[1] = f * (s1 + d * s0);
        fit[2] = f * (s2 + 2.0 * d * s1 + d2 * s0);
        fit[3] = f * (s3 + 3.0 * d * s2 + 3.0 * d2 * s1 + d2 * d * s0);
        fit[4] = f * (s4 + 4.0 * d * s3 + 6.0 * d2 * s2 + 4.0 * d2 * d * s1 + d2 * d2 * s0);
        fit[5] = f * t0;
        fit[6] = f * (t1 + d * t0);
        fit[7] = f * (t2 + 2.0 * d * t1 + d2 * t0);
    }
    fit[0] += 1.0;
    fit[5] += value;
    fit[8] += 1.0;
}

/* _ForgettingPolyFit.coefficients (degree 2): c1, c2 (c0 is not used). */
EXACT_ARITHMETIC static void fit_slopes(const double *fit, double *c1, double *c2)
{
    const double a00 = fit[0], a01 = fit[1], a02 = fit[2], a12 = fit[3], a22 = fit[4];
    const double t0 = fit[5], t1 = fit[6], t2 = fit[7], count = fit[8];
    if (count >= 3.0) {     /* _parabola_coefficients */
        const double a11 = a02;
        const double m00 = a11 * a22 - a12 * a12;
        const double m01 = a02 * a12 - a01 * a22;
        const double m02 = a01 * a12 - a02 * a11;
        const double det = a00 * m00 + a01 * m01 + a02 * m02;
        if (fabs(det) > 1e-12 * fabs(a00 * a11 * a22)) {
            const double m11 = a00 * a22 - a02 * a02;
            const double m12 = a01 * a02 - a00 * a12;
            const double m22 = a00 * a11 - a01 * a01;
            *c1 = (m01 * t0 + m11 * t1 + m12 * t2) / det;
            *c2 = (m02 * t0 + m12 * t1 + m22 * t2) / det;
            return;
        }
    }
    *c2 = 0.0;              /* _line_coefficients */
    const double det = a00 * a02 - a01 * a01;
    if (count < 2.0 || fabs(det) <= 1e-12 * a00 * a02)
        *c1 = 0.0;
    else
        *c1 = (a00 * t1 - a01 * t0) / det;
}

/* wrap_angle: [0, 2 pi). */
static double wrap_angle(double angle)
{
    double wrapped = fmod(angle, TWO_PI);
    if (wrapped < 0.0)
        wrapped += TWO_PI;
    return wrapped < TWO_PI ? wrapped : 0.0;
}

/* CrankRateFilter.update; speed NaN (or infinite) when not measured. out: wrapped angle,
   speed, acceleration, advance. */
EXACT_ARITHMETIC static void filter_update(double *st, double time_s, double angle,
                                           double speed, double *out)
{
    const int has_speed = isfinite(speed);
    const double mode = has_speed ? MODE_SPEED : MODE_ANGLE;
    double *speed_fit = st + F_SPEED_FIT, *angle_fit = st + F_ANGLE_FIT;
    if (st[F_STARTED] == 0.0) {
        st[F_STARTED] = 1.0;
        st[F_TIME] = time_s;
        st[F_ANGLE] = angle;
        st[F_MODE] = mode;
        st[F_SPEED] = has_speed ? speed : 0.0;
        st[F_ACCEL] = 0.0;
        fit_add(has_speed ? speed_fit : angle_fit, 0.0, 1.0, 0.0, 0.0);
        out[0] = wrap_angle(st[F_ANGLE]);
        out[1] = st[F_SPEED];
        out[2] = st[F_ACCEL];
        out[3] = st[F_ADVANCE];
        return;
    }
    const double tc = st[F_TC];
    const double dt = time_s - st[F_TIME];
    st[F_MEAN_DT] = isnan(st[F_MEAN_DT]) ? dt : 0.9 * st[F_MEAN_DT] + 0.1 * dt;
    const double span = st[F_MIN_SAMPLES] * st[F_MEAN_DT];
    const double tau = span > tc ? span : tc;     /* max(tc, span) */
    const double forget = exp(-dt / tau);
    double shift = dt / tc;
    const double predicted = has_speed ? 0.5 * (st[F_SPEED] + speed) * dt
                                       : st[F_SPEED] * dt + 0.5 * st[F_ACCEL] * dt * dt;
    const double advance = predicted
        + (python_mod(angle - st[F_ANGLE] - predicted + PI, TWO_PI) - PI);
    st[F_ANGLE] += advance;
    st[F_ADVANCE] = advance;
    st[F_TIME] = time_s;
    if (mode != st[F_MODE]) {
        memset(speed_fit, 0, 9 * sizeof(double));
        memset(angle_fit, 0, 9 * sizeof(double));
        st[F_MODE] = mode;
        shift = 0.0;
    }
    double c1, c2;
    if (has_speed) {
        fit_add(speed_fit, shift, forget, speed - st[F_SPEED], 0.0);
        fit_slopes(speed_fit, &c1, &c2);
        st[F_SPEED] = speed;
        st[F_ACCEL] = c1 / tc;
    }
    else {
        fit_add(angle_fit, shift, forget, advance, 0.0);
        fit_slopes(angle_fit, &c1, &c2);
        if (angle_fit[8] < 2.0) {
            st[F_SPEED] = advance / dt;
            st[F_ACCEL] = 0.0;
        }
        else {
            st[F_SPEED] = c1 / tc;
            st[F_ACCEL] = 2.0 * c2 / pow(tc, 2.0);
        }
    }
    out[0] = wrap_angle(st[F_ANGLE]);
    out[1] = st[F_SPEED];
    out[2] = st[F_ACCEL];
    out[3] = advance;
}

PyDoc_STRVAR(filter_update_doc,
"filter_update(state, time_s, angle, speed) -> (angle, speed, accel)\n"
"\n"
"CrankRateFilter.update on a state array (native.FILTER_STATE float64 values); speed NaN\n"
"when not measured. Returns the wrapped angle, speed and acceleration.");

static PyObject *filter_update_py(PyObject *module, PyObject *args)
{
    PyObject *state_object;
    double time_s, angle, speed, out[4];
    Py_buffer state = {0};
    (void)module;
    if (!PyArg_ParseTuple(args, "Oddd", &state_object, &time_s, &angle, &speed)
        || get_buffer(state_object, &state, 1, "state", FILTER_STATE) != 0)
        return NULL;
    filter_update(state.buf, time_s, angle, speed, out);
    PyBuffer_Release(&state);
    return Py_BuildValue("(ddd)", out[0], out[1], out[2]);
}

PyDoc_STRVAR(filter_signal_doc,
"filter_signal(state, times, angles, speeds, motion)\n"
"\n"
"filter_update over a signal (speeds NaN where not measured): motion (n x 4) receives the\n"
"wrapped angle, speed, acceleration and advance of every sample.");

static PyObject *filter_signal_py(PyObject *module, PyObject *args)
{
    PyObject *objects[5];
    Py_buffer state = {0}, times = {0}, angles = {0}, speeds = {0}, motion = {0};
    PyObject *result = NULL;
    (void)module;
    if (!PyArg_ParseTuple(args, "OOOOO", &objects[0], &objects[1], &objects[2], &objects[3],
                          &objects[4]))
        return NULL;
    if (get_buffer(objects[0], &state, 1, "state", FILTER_STATE) != 0
        || get_buffer(objects[1], &times, 0, "times", -1) != 0)
        goto done;
    const Py_ssize_t count = times.len / 8;
    if (get_buffer(objects[2], &angles, 0, "angles", count) != 0
        || get_buffer(objects[3], &speeds, 0, "speeds", count) != 0
        || get_buffer(objects[4], &motion, 1, "motion", 4 * count) != 0)
        goto done;
    const double *t = times.buf, *a = angles.buf, *w = speeds.buf;
    double *m = motion.buf;
    for (Py_ssize_t n = 0; n < count; n++)
        filter_update(state.buf, t[n], a[n], w[n], m + 4 * n);
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&state);
    PyBuffer_Release(&times);
    PyBuffer_Release(&angles);
    PyBuffer_Release(&speeds);
    PyBuffer_Release(&motion);
    return result;
}

/* ---- joint criteria: step.joint_criteria, the same arithmetic ----------------------- */

PyDoc_STRVAR(criteria_doc,
"criteria(record, near_zero_fraction, floor_fraction) -> (R, gamma_dot, ratio, near_zero)\n"
"\n"
"step.joint_criteria from a record (native.RECORD_SIZE): per joint the reaction\n"
"magnitude R, its direction's rate gamma_dot = (Fx dFy - Fy dFx) / R^2 with R^2 clamped to\n"
"floor_fraction^2 of the cycle mean square, |gamma_dot| / R, and whether R is below\n"
"near_zero_fraction of the cycle RMS (four-tuples).");

/* Per joint R, gamma_dot, |gamma_dot| / R and near zero of a record's joint part (v). */
EXACT_ARITHMETIC static void joint_criteria(const double *v, double near_zero_fraction,
                                            double floor_fraction, double *reactions,
                                            double *gamma_dots, double *ratios, int *near)
{
    const double limit2 = near_zero_fraction * near_zero_fraction;
    const double floor2 = floor_fraction * floor_fraction;
    for (int j = 0; j < 4; j++) {
        const double fx = v[2 * j], fy = v[2 * j + 1], rms2 = v[16 + j];
        double r2 = fx * fx + fy * fy;
        near[j] = r2 < limit2 * rms2;
        reactions[j] = gamma_dots[j] = ratios[j] = 0.0;
        const double floored = floor2 * rms2;
        if (floored > r2)
            r2 = floored;
        if (r2 > 0.0) {
            const double magnitude = sqrt(r2);
            const double gamma_dot = (fx * v[9 + 2 * j] - fy * v[8 + 2 * j]) / r2;
            reactions[j] = sqrt(fx * fx + fy * fy);
            gamma_dots[j] = gamma_dot;
            ratios[j] = fabs(gamma_dot) / magnitude;
        }
    }
}

static PyObject *criteria_py(PyObject *module, PyObject *args)
{
    PyObject *record_object;
    double near_zero_fraction, floor_fraction;
    Py_buffer record_view = {0};
    (void)module;
    if (!PyArg_ParseTuple(args, "Odd", &record_object, &near_zero_fraction, &floor_fraction)
        || get_buffer(record_object, &record_view, 0, "record", RECORD_SIZE) != 0)
        return NULL;
    double reactions[4], gamma_dots[4], ratios[4];
    int near[4];
    joint_criteria((const double *)record_view.buf + 2 * OUTPUTS, near_zero_fraction,
                   floor_fraction, reactions, gamma_dots, ratios, near);
    PyBuffer_Release(&record_view);
    return Py_BuildValue("((dddd)(dddd)(dddd)(NNNN))", reactions[0], reactions[1],
                         reactions[2], reactions[3], gamma_dots[0], gamma_dots[1],
                         gamma_dots[2], gamma_dots[3], ratios[0], ratios[1], ratios[2],
                         ratios[3], PyBool_FromLong(near[0]), PyBool_FromLong(near[1]),
                         PyBool_FromLong(near[2]), PyBool_FromLong(near[3]));
}

/* ---- the streaming update of an ordinary sample: StreamingEstimator.update in one call --- */

/*
 * Update.sample does what StreamingEstimator.update does for a sample the gate passes as a
 * plain step: the gate's checks, the crank filter, the clipping and flags, the step row, the
 * step (step_sample), the record, the criteria, the deflection bound, the validity indicator
 * and the Sample. Anything else (no reference yet, a start, repeat, outlier or gap, a
 * non-finite input or filter state, a failed step, an estimate beyond the bound) returns None
 * with z, prev and the filter as they were on entry and the gate's reference unchanged, and
 * the Python path takes the sample (core/estimation/compiled_update.py arms and disarms this
 * path around it).
 */

/* Why the last sample was left to the Python path (Update.fallback). */
enum {
    FALLBACK_NONE, FALLBACK_NOT_ARMED, FALLBACK_INPUT, FALLBACK_GATE, FALLBACK_FILTER,
    FALLBACK_STEP, FALLBACK_BOUND
};
enum { FLAG_LARGE_STEP, FLAG_CLIPPED_SPEED, FLAG_CLIPPED_ACCEL, FLAG_SPEED_FROM_ANGLE, FLAGS };
#define SAMPLE_FIELDS 15
/* sample.Sample's fields, in the order new_sample fills them (checked against the class) */
static const char *const SAMPLE_NAMES[SAMPLE_FIELDS] = {
    "stamp_ns", "crank_angle", "crank_speed", "crank_accel", "lever_tip", "coupler_mid",
    "reaction_n", "gamma_dot", "criterion", "near_zero", "error_indicator", "flags", "message",
    "modal", "nonlinearity"};

typedef struct {
    PyObject_HEAD
    Step step;
    Py_buffer views[STEP_VIEWS];
    Py_buffer z, prev, filter, record, context, indicator;  /* indicator: none without tables */
    double *saved;                  /* z, prev, the filter and the step's history on entry */
    PyObject *sample_type, *empty;
    Py_ssize_t slots[SAMPLE_FIELDS];    /* Sample's slot offsets; slots[0] < 0: call Sample */
    /* the estimator's and its gate's parameters */
    double speed_max, accel_limit, large_step_s, reset_gap_s, speed_bound, jump_accel,
           jump_allowance, angle_allowance, near_zero_fraction, floor_fraction,
           deflection_bound, error_floor;
    long long max_substep_ns;
    long base_flags, flags[FLAGS];
    /* the gate's reference (the last accepted sample) and the filter's time origin */
    int armed, fallback;
    long long last_stamp, stamp0, taken;
    double last_angle, last_speed;  /* speed NaN: none measured */
} Update;

/* a - b in *out, or 0 if it overflows. */
static int difference(long long a, long long b, long long *out)
{
    if ((b > 0 && a < LLONG_MIN + b) || (b < 0 && a > LLONG_MAX + b))
        return 0;
    *out = a - b;
    return 1;
}

/* The sample's stamp, angle and speed (NaN: None) as update() converts them; -1 if not a plain
   case (no exception left set). */
static int read_sample(PyObject *const *args, long long *stamp, double *angle, double *speed)
{
    int overflow = 0;
    PyObject *index = PyLong_Check(args[0]) ? Py_NewRef(args[0])
                      : PyIndex_Check(args[0]) ? PyNumber_Index(args[0]) : NULL;
    if (index != NULL) {
        *stamp = PyLong_AsLongLongAndOverflow(index, &overflow);
        Py_DECREF(index);
        *angle = PyFloat_AsDouble(args[1]);
        *speed = args[2] == Py_None ? NAN : PyFloat_AsDouble(args[2]);
    }
    if (index == NULL || overflow || PyErr_Occurred()) {
        PyErr_Clear();
        return -1;
    }
    return isfinite(*angle) ? 0 : -1;
}

/* InputGate.decide's checks of a STEP after the reference (dt_ns: the interval); 0 if the
   sample is anything else (a START, REPEATED or OUTLIER for the Python path). */
EXACT_ARITHMETIC static int gate_passes(const Update *u, long long stamp, double angle,
                                        double speed, long long *dt_ns)
{
    if (!isnan(speed) && !(fabs(speed) <= u->speed_bound))
        return 0;
    if (!difference(stamp, u->last_stamp, dt_ns))
        return 0;
    const double dt = (double)*dt_ns * 1e-9;
    if (!(dt > 0.0) || dt > u->reset_gap_s)
        return 0;
    if (!isnan(speed) && !isnan(u->last_speed)
        && fabs(speed - u->last_speed) > u->jump_accel * dt + u->jump_allowance)
        return 0;
    const double advance = fabs(python_mod(angle - u->last_angle + PI, TWO_PI) - PI);
    return !(advance > u->speed_bound * dt + u->angle_allowance);
}

/* A tuple of n floats, or NULL with an exception set. Not tracked by the garbage collector
   (floats cannot form a cycle; the collector would untrack it at its first pass). */
static PyObject *float_tuple(const double *values, Py_ssize_t n)
{
    PyObject *tuple = PyTuple_New(n);
    for (Py_ssize_t i = 0; tuple != NULL && i < n; i++) {
        PyObject *value = PyFloat_FromDouble(values[i]);
        if (value == NULL)
            Py_CLEAR(tuple);
        else
            PyTuple_SET_ITEM(tuple, i, value);
    }
    if (tuple != NULL)
        PyObject_GC_UnTrack(tuple);
    return tuple;
}

/* The tuple of four bools of the near-zero flags (bit j: joint j), kept per flag pattern. */
static PyObject *near_zero_tuple(const int *near)
{
    static PyObject *patterns[16];
    const int bits = (near[0] != 0) | (near[1] != 0) << 1 | (near[2] != 0) << 2
                     | (near[3] != 0) << 3;
    if (patterns[bits] == NULL) {
        patterns[bits] = PyTuple_Pack(4, near[0] ? Py_True : Py_False,
                                      near[1] ? Py_True : Py_False,
                                      near[2] ? Py_True : Py_False,
                                      near[3] ? Py_True : Py_False);
        if (patterns[bits] == NULL)
            return NULL;
    }
    return Py_NewRef(patterns[bits]);
}

/* sample_from_record's error indicator: |correction| / max(|deflection|, floor), summed
   left to right as its sum(). */
EXACT_ARITHMETIC static double error_indicator(const double *record, double floor)
{
    double size2 = 0.0, correction2 = 0.0;
    for (int o = 0; o < OUTPUTS; o++) {
        size2 += record[o] * record[o];
        correction2 += record[OUTPUTS + o] * record[OUTPUTS + o];
    }
    const double size = sqrt(size2);
    return sqrt(correction2) / (floor > size ? floor : size);
}

/* The reduced model's [q, q'] of the newest sample: z, or its lift on the soft basis. */
static const double *reduced_state(const Update *u)
{
    return u->step.lift_phi != NULL ? u->step.lifted : u->z.buf;
}

/*
 * The Sample of the new state (record, z) at crank (angle, speed, accel), its fields as
 * sample_from_record fills them: written into the slots of a new instance (what the
 * dataclass's __init__ does, without its Python frame: about 0.2 us), or Sample called.
 */
static PyObject *new_sample(Update *u, long long stamp, const double *crank, long flags,
                            double indicator)
{
    const double *record = u->record.buf;
    double reactions[3][4];
    int near[4];
    joint_criteria(record + 2 * OUTPUTS, u->near_zero_fraction, u->floor_fraction,
                   reactions[0], reactions[1], reactions[2], near);
    PyObject *fields[SAMPLE_FIELDS] = {
        PyLong_FromLongLong(stamp), PyFloat_FromDouble(crank[0]),
        PyFloat_FromDouble(crank[1]), PyFloat_FromDouble(crank[2]), float_tuple(record, 2),
        float_tuple(record + 2, 2), float_tuple(reactions[0], 4), float_tuple(reactions[1], 4),
        float_tuple(reactions[2], 4),
        near_zero_tuple(near),
        PyFloat_FromDouble(error_indicator(record, u->error_floor)),
        PyLong_FromLong(flags | u->base_flags), Py_NewRef(u->empty),
        float_tuple(reduced_state(u), u->step.rr), PyFloat_FromDouble(indicator)};
    PyObject *sample = NULL;
    int complete = 1;
    for (int i = 0; i < SAMPLE_FIELDS; i++)
        complete &= fields[i] != NULL;
    if (complete && u->slots[0] >= 0) {
        PyTypeObject *type = (PyTypeObject *)u->sample_type;
        sample = type->tp_alloc(type, 0);
        for (int i = 0; sample != NULL && i < SAMPLE_FIELDS; i++)
            *(PyObject **)((char *)sample + u->slots[i]) = fields[i];    /* takes the ref */
        if (sample != NULL)
            return sample;
    }
    else if (complete) {
        sample = PyObject_Vectorcall(u->sample_type, fields, SAMPLE_FIELDS, NULL);
    }
    for (int i = 0; i < SAMPLE_FIELDS; i++)
        Py_XDECREF(fields[i]);
    return sample;
}

/* Put z, prev and the filter back as they were on entry; return None (the Python path). */
static PyObject *fall_back(Update *u, int reason)
{
    const Py_ssize_t n = 2 * u->step.r + 1;
    memcpy(u->z.buf, u->saved, (size_t)n * sizeof(double));
    memcpy(u->prev.buf, u->saved + n, 3 * sizeof(double));
    memcpy(u->filter.buf, u->saved + n + 3, FILTER_STATE * sizeof(double));
    if (u->step.history != NULL)
        memcpy(u->step.history, u->saved + n + 3 + FILTER_STATE,
               (size_t)history_size(&u->step) * sizeof(double));
    u->fallback = reason;
    Py_RETURN_NONE;
}

/* StreamingEstimator._advance_to and _finish for a gated step; None to fall back. */
EXACT_ARITHMETIC static PyObject *advance_sample(Update *u, long long stamp, double angle,
                                                 double speed, long long dt_ns)
{
    const Py_ssize_t n = 2 * u->step.r + 1;
    long long since;
    if (!difference(stamp, u->stamp0, &since)) {
        u->fallback = FALLBACK_GATE;
        Py_RETURN_NONE;
    }
    memcpy(u->saved, u->z.buf, (size_t)n * sizeof(double));
    memcpy(u->saved + n, u->prev.buf, 3 * sizeof(double));
    memcpy(u->saved + n + 3, u->filter.buf, FILTER_STATE * sizeof(double));
    if (u->step.history != NULL)
        memcpy(u->saved + n + 3 + FILTER_STATE, u->step.history,
               (size_t)history_size(&u->step) * sizeof(double));
    double crank[4];        /* wrapped angle, speed, accel, advance */
    filter_update(u->filter.buf, (double)since * 1e-9, angle, speed, crank);
    const double dt = (double)dt_ns * 1e-9;
    long flags = (isnan(speed) ? u->flags[FLAG_SPEED_FROM_ANGLE] : 0)
                 | (dt > u->large_step_s ? u->flags[FLAG_LARGE_STEP] : 0);
    if (!(isfinite(crank[0]) && isfinite(crank[1]) && isfinite(crank[2])))
        return fall_back(u, FALLBACK_FILTER);
    double row[ROW_FIELDS] = {dt, (double)(dt_ns / u->max_substep_ns
                                           + (dt_ns % u->max_substep_ns != 0)),
                              crank[0], crank[1], crank[2], crank[3]};
    if (fabs(crank[1]) > u->speed_max) {
        row[3] = copysign(u->speed_max, crank[1]);
        flags |= u->flags[FLAG_CLIPPED_SPEED];
    }
    if (fabs(crank[2]) > u->accel_limit) {
        row[4] = copysign(u->accel_limit, crank[2]);
        flags |= u->flags[FLAG_CLIPPED_ACCEL];
    }
    if (step_sample(&u->step, u->z.buf, u->prev.buf, row, u->record.buf) != SAMPLE_DONE)
        return fall_back(u, FALLBACK_STEP);
    const double *record = u->record.buf;
    double largest = fabs(record[0]);       /* max() of the deflections, NaN as max() does */
    for (int o = 1; o < OUTPUTS; o++)
        largest = fabs(record[o]) > largest ? fabs(record[o]) : largest;
    if (!(largest <= u->deflection_bound))
        return fall_back(u, FALLBACK_BOUND);
    double indicator = NAN;
    if (u->indicator.buf != NULL) {
        const double clipped = -u->accel_limit > crank[2] ? -u->accel_limit : crank[2];
        indicator = indicator_value(u->context.buf, u->indicator.buf, reduced_state(u), crank[0],
                                    crank[1], u->accel_limit < clipped ? u->accel_limit
                                                                       : clipped);
    }
    PyObject *sample = new_sample(u, stamp, crank, flags, indicator);
    if (sample == NULL) {       /* no memory: raise with the state as it was */
        Py_DECREF(fall_back(u, FALLBACK_NONE));
        return NULL;
    }
    u->last_stamp = stamp;
    u->last_angle = angle;
    u->last_speed = speed;
    u->taken++;
    return sample;
}

static PyObject *update_sample(Update *u, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "sample(stamp_ns, crank_angle, crank_speed)");
        return NULL;
    }
    long long stamp, dt_ns;
    double angle, speed;
    u->fallback = !u->armed ? FALLBACK_NOT_ARMED
                  : read_sample(args, &stamp, &angle, &speed) != 0 ? FALLBACK_INPUT
                  : !gate_passes(u, stamp, angle, speed, &dt_ns) ? FALLBACK_GATE
                  : FALLBACK_NONE;
    if (u->fallback != FALLBACK_NONE)
        Py_RETURN_NONE;
    return advance_sample(u, stamp, angle, speed, dt_ns);
}

static PyObject *update_arm(Update *u, PyObject *args)
{
    PyObject *speed_object;
    long long stamp, stamp0;
    double angle;
    if (!PyArg_ParseTuple(args, "LdOL", &stamp, &angle, &speed_object, &stamp0))
        return NULL;
    const double speed = speed_object == Py_None ? NAN : PyFloat_AsDouble(speed_object);
    if (PyErr_Occurred())
        return NULL;
    u->last_stamp = stamp;
    u->last_angle = angle;
    u->last_speed = speed;
    u->stamp0 = stamp0;
    u->armed = 1;
    Py_RETURN_NONE;
}

static PyObject *update_disarm(Update *u, PyObject *unused)
{
    (void)unused;
    u->armed = 0;
    Py_RETURN_NONE;
}

static PyObject *update_reference(Update *u, PyObject *unused)
{
    (void)unused;
    if (isnan(u->last_speed))
        return Py_BuildValue("(LdO)", u->last_stamp, u->last_angle, Py_None);
    return Py_BuildValue("(Ldd)", u->last_stamp, u->last_angle, u->last_speed);
}

static void update_dealloc(Update *u)
{
    step_close(&u->step, u->views);
    PyBuffer_Release(&u->z);
    PyBuffer_Release(&u->prev);
    PyBuffer_Release(&u->filter);
    PyBuffer_Release(&u->record);
    PyBuffer_Release(&u->context);
    PyBuffer_Release(&u->indicator);
    free(u->saved);
    Py_XDECREF(u->sample_type);
    Py_XDECREF(u->empty);
    Py_TYPE(u)->tp_free((PyObject *)u);
}

/*
 * Take the Sample class: its fields (`fields`, in order) must be SAMPLE_NAMES. Where each is
 * a plain slot (a member descriptor of an object) and nothing runs after __init__, note the
 * slots' offsets; otherwise samples are made by calling the class.
 */
static int take_sample_type(Update *u, PyObject *sample_type, PyObject *fields)
{
    int same = PyTuple_Check(fields) && PyTuple_GET_SIZE(fields) == SAMPLE_FIELDS;
    for (int i = 0; same && i < SAMPLE_FIELDS; i++) {
        PyObject *name = PyTuple_GET_ITEM(fields, i);
        same = PyUnicode_Check(name) && PyUnicode_CompareWithASCIIString(name, SAMPLE_NAMES[i])
                                        == 0;
    }
    if (!same || !PyType_Check(sample_type)) {
        PyErr_SetString(PyExc_ValueError, "`sample_type` must be a class with the fields of "
                        "sample.Sample, in order");
        return -1;
    }
    u->sample_type = Py_NewRef(sample_type);
    u->slots[0] = -1;
    int plain = !PyObject_HasAttrString(sample_type, "__post_init__");
    for (int i = 0; plain && i < SAMPLE_FIELDS; i++) {
        PyObject *slot = PyObject_GetAttrString(sample_type, SAMPLE_NAMES[i]);
        plain = slot != NULL && Py_IS_TYPE(slot, &PyMemberDescr_Type)
                && ((PyMemberDescrObject *)slot)->d_member->type == T_OBJECT_EX
                && !(((PyMemberDescrObject *)slot)->d_member->flags & READONLY);
        if (plain)
            u->slots[i] = ((PyMemberDescrObject *)slot)->d_member->offset;
        Py_XDECREF(slot);
    }
    PyErr_Clear();
    if (!plain)
        u->slots[0] = -1;
    return 0;
}

/* The validity indicator's (context, table), checked; none if `indicator` is None. */
static int take_indicator(Update *u, PyObject *indicator)
{
    PyObject *context, *table;
    if (indicator == Py_None)
        return 0;
    if (!PyArg_ParseTuple(indicator, "OO;`indicator` must be None or (context, table)",
                          &context, &table)
        || get_buffer(context, &u->context, 0, "context", -1) != 0)
        return -1;
    const double *values = u->context.buf;
    const Py_ssize_t length = u->context.len / 8;
    if (length < INDICATOR_HEADER || indicator_context_size(values, length) != length
        || values[INDICATOR_SIZE] != (double)u->step.rr) {
        PyErr_SetString(PyExc_ValueError, "`indicator` context does not fit the model");
        return -1;
    }
    return get_buffer(table, &u->indicator, 0, "indicator table", indicator_table_size(values));
}

/* The step (tables, second, lift, cells_per_radian, c1) and the state buffers into u. */
static int take_state(Update *u, PyObject *tables, PyObject *second, PyObject *lift,
                      double cells_per_radian, double c1, PyObject *const *state)
{
    if (!PyTuple_Check(tables) || PyTuple_GET_SIZE(tables) != STEP_TABLES) {
        PyErr_SetString(PyExc_TypeError, "`tables` must be (mass, damping, kf, out, joint, g0)");
        return -1;
    }
    if (get_buffer(state[0], &u->z, 1, "z", -1) != 0)
        return -1;
    const Py_ssize_t r = (u->z.len / 8 - 1) / 2;
    if (r < 1 || u->z.len / 8 != 2 * r + 1) {
        PyErr_SetString(PyExc_ValueError, "`z` must have 2 r + 1 values");
        return -1;
    }
    if (step_open(&u->step, r, &PyTuple_GET_ITEM(tables, 0), second, lift, cells_per_radian, c1,
                  u->views) != 0
        || get_buffer(state[1], &u->prev, 1, "prev", 3) != 0
        || get_buffer(state[2], &u->filter, 1, "filter", FILTER_STATE) != 0
        || get_buffer(state[3], &u->record, 1, "record", RECORD_SIZE) != 0)
        return -1;
    u->saved = malloc(sizeof(double) * (size_t)(2 * r + 1 + 3 + FILTER_STATE
                                                + history_size(&u->step)));
    if (u->saved == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    return 0;
}

static PyObject *update_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *keywords[] = {
        "tables", "second", "lift", "cells_per_radian", "c1", "z", "prev", "filter", "record",
        "indicator", "sample_type", "sample_fields", "speed_max", "accel_limit", "large_step_s", "reset_gap_s",
        "speed_bound", "jump_accel", "jump_allowance", "angle_allowance",
        "near_zero_fraction", "floor_fraction", "deflection_bound", "error_floor",
        "max_substep_ns", "base_flags", "flags", NULL};
    PyObject *tables, *second, *lift, *state[4], *indicator, *sample_type, *sample_fields;
    double cells_per_radian, c1;
    Update *u = (Update *)type->tp_alloc(type, 0);
    if (u == NULL)
        return NULL;
    if (!PyArg_ParseTupleAndKeywords(
            args, kwargs, "$OOOddOOOOOOOddddddddddddLl(llll):Update", keywords, &tables,
            &second, &lift, &cells_per_radian, &c1, &state[0], &state[1], &state[2], &state[3],
            &indicator, &sample_type, &sample_fields, &u->speed_max, &u->accel_limit, &u->large_step_s,
            &u->reset_gap_s, &u->speed_bound, &u->jump_accel, &u->jump_allowance,
            &u->angle_allowance, &u->near_zero_fraction, &u->floor_fraction,
            &u->deflection_bound, &u->error_floor, &u->max_substep_ns, &u->base_flags,
            &u->flags[0], &u->flags[1], &u->flags[2], &u->flags[3])
        || take_state(u, tables, second, lift, cells_per_radian, c1, state) != 0
        || take_indicator(u, indicator) != 0
        || take_sample_type(u, sample_type, sample_fields) != 0)
        goto fail;
    if (!(u->max_substep_ns > 0)) {
        PyErr_SetString(PyExc_ValueError, "`max_substep_ns` must be positive");
        goto fail;
    }
    u->empty = PyUnicode_FromString("");
    if (u->empty == NULL)
        goto fail;
    u->last_speed = NAN;
    return (PyObject *)u;
fail:
    Py_DECREF(u);
    return NULL;
}

static PyMethodDef update_methods[] = {
    {"sample", (PyCFunction)(void (*)(void))update_sample, METH_FASTCALL,
     "sample(stamp_ns, crank_angle, crank_speed) -> Sample or None\n\n"
     "StreamingEstimator.update of an ordinary sample (armed, a plain step): the Sample, the\n"
     "state advanced and the reference moved on; otherwise None, nothing changed (see\n"
     "`fallback`), for the Python path."},
    {"arm", (PyCFunction)update_arm, METH_VARARGS,
     "arm(last_stamp_ns, last_angle, last_speed, stamp0_ns)\n\n"
     "Take the gate's reference (the last accepted sample; speed None if it had none) and\n"
     "the filter's time origin: sample() runs from here on."},
    {"disarm", (PyCFunction)update_disarm, METH_NOARGS,
     "disarm()\n\nsample() returns None until arm() is called again."},
    {"reference", (PyCFunction)update_reference, METH_NOARGS,
     "reference() -> (stamp_ns, angle, speed or None)\n\n"
     "The gate's reference: the last sample accepted (by this path, or as armed)."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef update_members[] = {
    {"armed", T_INT, offsetof(Update, armed), READONLY, "Whether sample() runs."},
    {"fallback", T_INT, offsetof(Update, fallback), READONLY,
     "Why the last sample() returned None (FALLBACK_* of _radau_step.c; 0: it did not)."},
    {"taken", T_LONGLONG, offsetof(Update, taken), READONLY,
     "Samples this path estimated."},
    {"fills_slots", T_PYSSIZET, offsetof(Update, slots), READONLY,
     "Offset of the first slot Samples are written into (>= 0), or -1: Sample is called."},
    {"deflection_bound", T_DOUBLE, offsetof(Update, deflection_bound), 0,
     "The estimator's deflection bound [m] (StreamingEstimator.deflection_bound_m)."},
    {NULL, 0, 0, 0, NULL},
};

static PyTypeObject UpdateType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "flexlink_ros.core.estimation._radau_step.Update",
    .tp_basicsize = sizeof(Update),
    .tp_dealloc = (destructor)update_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Update(*, tables, second, cells_per_radian, c1, z, prev, filter, record, "
              "indicator, sample_type, sample_fields, <the estimator's parameters>)\n\n"
              "StreamingEstimator.update of an ordinary sample in one call "
              "(core/estimation/compiled_update.py builds it).",
    .tp_methods = update_methods,
    .tp_members = update_members,
    .tp_new = update_new,
};

PyDoc_STRVAR(lu_solve_doc,
"lu_solve(a, b)\n"
"\n"
"Solve a x = b in place (a: n x n float64 C order, overwritten by its LU factors; b: n,\n"
"overwritten by x), the step's blocked LU with partial pivoting; for tests.");

static PyObject *lu_solve(PyObject *module, PyObject *args)
{
    PyObject *a_object, *b_object;
    Py_buffer a = {0}, b = {0};
    PyObject *result = NULL;
    (void)module;
    if (!PyArg_ParseTuple(args, "OO", &a_object, &b_object))
        return NULL;
    if (get_buffer(b_object, &b, 1, "b", -1) != 0)
        return NULL;
    const Py_ssize_t n = b.len / 8;
    if (n < 1 || get_buffer(a_object, &a, 1, "a", n * n) != 0) {
        if (n < 1)
            PyErr_SetString(PyExc_ValueError, "`b` is empty");
        goto done;
    }
    if (solve(n, a.buf, b.buf) != 0) {
        PyErr_SetString(PyExc_ValueError, "singular matrix");
        goto done;
    }
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&a);
    PyBuffer_Release(&b);
    return result;
}

static PyMethodDef methods[] = {
    {"lu_solve", lu_solve, METH_VARARGS, lu_solve_doc},
    {"advance", advance, METH_VARARGS, advance_doc},
    {"filter_update", filter_update_py, METH_VARARGS, filter_update_doc},
    {"filter_signal", filter_signal_py, METH_VARARGS, filter_signal_doc},
    {"criteria", criteria_py, METH_VARARGS, criteria_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_radau_step",
    "Compiled per-sample Radau IIA step of the streaming estimator (core/estimation/step.py).",
    -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__radau_step(void)
{
    if (PyType_Ready(&UpdateType) < 0)
        return NULL;
    PyObject *module = PyModule_Create(&module_def);
    if (module != NULL && PyModule_AddObjectRef(module, "Update", (PyObject *)&UpdateType) < 0)
        Py_CLEAR(module);
    return module;
}
