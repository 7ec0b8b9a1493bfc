/*
 * The reduced nonlinear model stepped through samples, compiled: the twin of
 * NonlinearStepper's numpy step in flexlink_ros/core/estimation/nonlinear_stream.py (its
 * reference; a test compares the two). Plain C API, no numpy headers.
 *
 * march(...): see its notes below. One call steps one sample or many (offline); a Stepper
 * (one estimator's step, its buffers taken once) steps the streaming update's samples. Per
 * step the tables are read at the stage angles by cubic Hermite interpolation (only the
 * fields the step uses; both stages in one pass over the rows of the grid nodes they share),
 * the linear part is formed from them, and the stage accelerations are solved by simplified
 * Newton (the Jacobian formed at the step's start and again when an iteration contracts by
 * less than half); a step that fails is retried as two halves. No Python object is touched
 * between the samples.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "_doubles.h"
#include "_pivot.h"

/* The hot loops also built for AVX2, chosen at load time where the CPU has it (GCC, x86-64,
 * glibc: the choice is an ifunc). */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__GLIBC__)
#define VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define VECTOR_CLONES
#endif


typedef struct {
    const double *mass, *damping, *stiffness, *load, *chord, *chord_rate, *shortening,
        *shortening_rate, *k, *speed, *q, *v, *a, *a2, *c;
    double *acc, *axial;
    Py_ssize_t s, m, e;
    double h, beta;
    int nonlinear;
} Problem;

/* Lumped force change (force: s m) and, if fq, its tangents (fq, fv: s m m, added to). */
VECTOR_CLONES static void lumped(const Problem *p, const double *disp, const double *vel,
                                 double *force, double *fq, double *fv, double *axial_last,
                                 double *work)
{
    const Py_ssize_t m = p->m, e = p->e;
    double *ht = work, *grad = work + m, *dax = work + 2 * m, *sq = work + 3 * m;
    memset(force, 0, (size_t)(p->s * m) * sizeof(double));
    for (Py_ssize_t i = 0; i < p->s; i++) {
        const double w = p->speed[i], *x = disp + i * m, *xd = vel + i * m;
        for (Py_ssize_t l = 0; l < e; l++) {
            const double *ch = p->chord + (i * e + l) * m, *cr = p->chord_rate + (i * e + l) * m;
            const double *g = p->shortening + (i * e + l) * m * m;
            const double *hr = p->shortening_rate + (i * e + l) * m * m;
            const double k = p->k[l];
            double ce = 0.0, cv = 0.0, crx = 0.0;
#pragma omp simd reduction(+ : ce, cv, crx)
            for (Py_ssize_t a = 0; a < m; a++) {
                ce += ch[a] * x[a];
                cv += ch[a] * xd[a];
                crx += cr[a] * x[a];
            }
            const double lin = k * (ce + p->beta * (cv + w * crx));
            if (!p->nonlinear) {
                if (i == p->s - 1)
                    axial_last[l] = lin;
                continue;
            }
            double half = 0.0, rate = 0.0, quad = 0.0;
            if (fq != NULL)
                memset(ht, 0, (size_t)m * sizeof(double));
            for (Py_ssize_t a = 0; a < m; a++) {
                const double *restrict ga = g + a * m, *restrict ha = hr + a * m;
                double sg = 0.0, sh = 0.0, sv = 0.0;
                if (fq != NULL) {       /* and g xd, h^T x for the tangents */
                    const double xa = x[a];
#pragma omp simd reduction(+ : sg, sh, sv)
                    for (Py_ssize_t b = 0; b < m; b++) {
                        sg += ga[b] * x[b];
                        sh += ha[b] * x[b];
                        sv += ga[b] * xd[b];
                        ht[b] += ha[b] * xa;
                    }
                } else {
#pragma omp simd reduction(+ : sg, sh)
                    for (Py_ssize_t b = 0; b < m; b++) {
                        sg += ga[b] * x[b];
                        sh += ha[b] * x[b];
                    }
                }
                sq[a] = sh;
                grad[a] = ch[a] + sg;
                dax[a] = sv;
                half += sg * x[a];
                quad += x[a] * sh;
            }
#pragma omp simd reduction(+ : rate)
            for (Py_ssize_t a = 0; a < m; a++)
                rate += grad[a] * xd[a];
            rate += w * (crx + quad);
            const double n = k * (ce + 0.5 * half + p->beta * rate);
            if (i == p->s - 1)
                axial_last[l] = n;
            double *f = force + i * m;
            for (Py_ssize_t a = 0; a < m; a++)
                f[a] += n * grad[a] - lin * ch[a];
            if (fq == NULL)
                continue;
            /* (h + h^T) x: sq holds h x, ht h^T x */
            for (Py_ssize_t a = 0; a < m; a++)
                dax[a] = k * (grad[a] + p->beta * (dax[a] + w * (cr[a] + sq[a] + ht[a])));
            const double bw = p->beta * w, bk = p->beta * k;
            double *restrict chw = sq;      /* sq is spent: ch + beta w cr */
            for (Py_ssize_t b = 0; b < m; b++)
                chw[b] = ch[b] + bw * cr[b];
            for (Py_ssize_t a = 0; a < m; a++) {
                double *restrict kq = fq + i * m * m + a * m, *restrict kv = fv + i * m * m + a * m;
                const double *restrict ga = g + a * m;
                const double grad_a = grad[a], kch_a = k * ch[a], ch_a = ch[a];
#pragma omp simd
                for (Py_ssize_t b = 0; b < m; b++) {
                    kq[b] += grad_a * dax[b] + n * ga[b] - kch_a * chw[b];
                    kv[b] += bk * (grad_a * grad[b] - ch_a * ch[b]);
                }
            }
        }
    }
}

/*
 * LU with partial pivoting in place (n x n, row-major); 0 if singular. Two columns per pass:
 * the second column's pivot is found after the first's elimination of that column alone, and
 * the rows below are then updated by both pivot rows in one sweep (each row read once per two
 * columns). The arithmetic of every entry is the one-column-at-a-time order's.
 */
VECTOR_CLONES static int lu_factor(double *a, Py_ssize_t n, Py_ssize_t *piv)
{
    Py_ssize_t col = 0;
    for (; col + 1 < n; col += 2) {
        const Py_ssize_t next = col + 1;
        double largest;     /* the pivot's magnitude (the zero test below is on the value) */
        piv[col] = pivot_row_of(a, n, col, col, &largest);
        swap_rows(a, n, col, piv[col]);
        if (a[col * n + col] == 0.0)
            return 0;
        const double inv = 1.0 / a[col * n + col];
        const double *restrict first = a + col * n;
        for (Py_ssize_t r = next; r < n; r++) {       /* column col, then column next */
            double *restrict row = a + r * n;
            row[next] -= (row[col] *= inv) * first[next];
        }
        piv[next] = pivot_row_of(a, n, next, next, &largest);
        swap_rows(a, n, next, piv[next]);
        double *restrict second = a + next * n;
        if (second[next] == 0.0)
            return 0;
        const double f = second[col];
        for (Py_ssize_t j = next + 1; j < n; j++)      /* the second pivot row's rest */
            second[j] -= f * first[j];
        const double inv2 = 1.0 / second[next];
        const Py_ssize_t len = n - next - 1;
        const double *restrict p0 = first + next + 1, *restrict p1 = second + next + 1;
        for (Py_ssize_t r = next + 1; r < n; r++) {
            double *restrict row = a + r * n;
            const double f0 = row[col], f1 = (row[next] *= inv2);
            double *restrict rest = row + next + 1;
#pragma omp simd
            for (Py_ssize_t j = 0; j < len; j++)
                rest[j] = (rest[j] - f0 * p0[j]) - f1 * p1[j];
        }
    }
    if (col < n) {          /* odd n: the last column */
        piv[col] = col;
        if (a[col * n + col] == 0.0)
            return 0;
    }
    return 1;
}

/* The LU factors transposed (lut: n x n), so that both substitutions run along rows. */
static void transpose(const double *a, Py_ssize_t n, double *lut)
{
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < n; j++)
            lut[j * n + i] = a[i * n + j];
}

/*
 * Solve with the LU factors (lut: transposed, piv: lu_factor's row swaps) in place. The swaps
 * touch only rows not yet reached, so they are applied first; each solved value is then
 * subtracted from the rows below (above) it, along a row of lut.
 */
VECTOR_CLONES static void lu_solve(const double *lut, Py_ssize_t n, const Py_ssize_t *piv,
                                   double *b)
{
    for (Py_ssize_t i = 0; i < n; i++) {
        const double t = b[piv[i]];
        b[piv[i]] = b[i];
        b[i] = t;
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        const double bj = b[j], *restrict column = lut + j * n;
        for (Py_ssize_t i = j + 1; i < n; i++)
            b[i] -= column[i] * bj;
    }
    for (Py_ssize_t j = n - 1; j >= 0; j--) {
        const double *restrict column = lut + j * n;
        const double bj = (b[j] /= column[j]);
        for (Py_ssize_t i = 0; i < j; i++)
            b[i] -= column[i] * bj;
    }
}

/* Stage states, the residual (res: s m) and, if jac, the step matrix (s m x s m). */
VECTOR_CLONES static void residual(const Problem *p, double *disp, double *vel, double *res,
                                   double *jac, double *fq, double *fv, double *work)
{
    const Py_ssize_t s = p->s, m = p->m, n = s * m;
    for (Py_ssize_t i = 0; i < s; i++)
        for (Py_ssize_t a = 0; a < m; a++) {
            double d = p->q[a] + p->c[i] * p->h * p->v[a], u = p->v[a];
            for (Py_ssize_t j = 0; j < s; j++) {
                d += p->h * p->h * p->a2[i * s + j] * p->acc[j * m + a];
                u += p->h * p->a[i * s + j] * p->acc[j * m + a];
            }
            disp[i * m + a] = d;
            vel[i * m + a] = u;
        }
    if (jac != NULL) {
        memset(fq, 0, (size_t)(s * m * m) * sizeof(double));
        memset(fv, 0, (size_t)(s * m * m) * sizeof(double));
    }
    lumped(p, disp, vel, res, jac != NULL ? fq : NULL, fv, p->axial, work);
    for (Py_ssize_t i = 0; i < s; i++) {
        const double *mm = p->mass + i * m * m, *cc = p->damping + i * m * m,
                     *kk = p->stiffness + i * m * m;
        for (Py_ssize_t a = 0; a < m; a++) {
            double r = 0.0;
#pragma omp simd reduction(+ : r)
            for (Py_ssize_t b = 0; b < m; b++)
                r += mm[a * m + b] * p->acc[i * m + b] + cc[a * m + b] * vel[i * m + b]
                     + kk[a * m + b] * disp[i * m + b];
            res[i * m + a] = r + (res[i * m + a] - p->load[i * m + a]);
        }
        if (jac == NULL)
            continue;
        const double *fvi = fv + i * m * m, *fqi = fq + i * m * m;
        for (Py_ssize_t j = 0; j < s; j++) {
            const double ha = p->h * p->a[i * s + j], hh = p->h * p->h * p->a2[i * s + j];
            const double diagonal = i == j ? 1.0 : 0.0;   /* the mass on the stage's own block */
            for (Py_ssize_t a = 0; a < m; a++) {
                double *restrict row = jac + (i * m + a) * n + j * m;
                const double *restrict ma = mm + a * m, *restrict ca = cc + a * m,
                                       *restrict ka = kk + a * m, *restrict va = fvi + a * m,
                                       *restrict qa = fqi + a * m;
#pragma omp simd
                for (Py_ssize_t b = 0; b < m; b++)
                    row[b] = diagonal * ma[b] + ha * (ca[b] + va[b]) + hh * (ka[b] + qa[b]);
            }
        }
    }
}

/* The step matrix's LU factors (valid: formed in this step). */
typedef struct {
    double *lu, *lut;
    Py_ssize_t *piv;
    int valid;
} Factor;

/*
 * Simplified Newton on the stage accelerations (p->acc holds the start): the step matrix is
 * formed at the first iteration and again whenever an iteration contracts by less than half.
 * An update `divergence` times the first one has left the start's basin (the cubic strain
 * has far roots a relative test would accept): not converged, so the step is halved.
 * Returns the iterations, 0 if not converged.
 */
static Py_ssize_t solve(Problem *p, double tolerance, double divergence, Py_ssize_t iterations,
                        double *mem, Factor *factor)
{
    const Py_ssize_t s = p->s, m = p->m, n = s * m;
    double *disp = mem, *vel = disp + n, *res = vel + n, *fq = res + n;
    double *fv = fq + s * m * m, *work = fv + s * m * m;
    double previous = INFINITY, first = INFINITY;
    for (Py_ssize_t count = 1; count <= iterations; count++) {
        const int form = !factor->valid;
        residual(p, disp, vel, res, form ? factor->lu : NULL, fq, fv, work);
        if (form) {
            if (!lu_factor(factor->lu, n, factor->piv))
                return 0;
            transpose(factor->lu, n, factor->lut);
            factor->valid = 1;
        }
        for (Py_ssize_t i = 0; i < n; i++)
            res[i] = -res[i];
        lu_solve(factor->lut, n, factor->piv, res);
        double size = 0.0, scale = 0.0;
        for (Py_ssize_t i = 0; i < n; i++) {
            p->acc[i] += res[i];
            /* as fmax (a NaN is passed over: the caller checks acc), without its call */
            const double du = fabs(res[i]), ua = fabs(p->acc[i]);
            size = du > size ? du : size;
            scale = ua > scale ? ua : scale;
        }
        if (!isfinite(size))
            return 0;
        if (size <= tolerance * scale || size == 0.0)
            return count;
        if (count == 1)
            first = size;
        else if (size > divergence * first)
            return 0;
        if (size > 0.5 * previous)
            factor->valid = 0;
        previous = size;
    }
    return 0;
}

/*
 * The tables over the crank angle and the model's constants (march's arguments).
 * off: the flat row's offsets of the FIELDS fields, in STEP_FIELDS order (nonlinear_stream.py):
 * mass, gyroscopic, coupling_a, coupling_w2, elastic, elastic_rate, geometric_1, geometric_a,
 * geometric_w2, load_1, load_a, load_w2, chord, chord_rate, shortening, shortening_rate, output.
 */
#define FIELDS 17
#define TWO_PI (2.0 * 3.141592653589793)

typedef struct {
    const double *values, *slopes, *off, *bearing, *k, *length, *a, *a2, *c;
    Py_ssize_t nodes, fields, s, m, e, outputs, iterations;
    double beta, tolerance, divergence;
    int nonlinear;
} Model;

/* The estimator's state: written only by a step that converges (NonlinearStepper's). */
typedef struct {
    double *q, *v, *guess, *axial, *slope, *output;
    int has_guess;
    Py_ssize_t iterations;
} State;

/* Workspace of one step. */
typedef struct {
    double *tables, *mem, *acc, *angles, *speed, *axial, *output, *raw;
    Factor factor;
} Work;

/* Cubic Hermite weights of the grid cell holding theta (NonlinearTables._interpolate). */
typedef struct {
    const double *p0, *p1, *d0, *d1;
    double w00, w10, w01, w11;
} Hermite;

static void hermite_at(const Model *md, double theta, Hermite *hm)
{
    double x = fmod(theta, TWO_PI);
    if (x < 0.0)
        x += TWO_PI;
    const double position = x * ((double)md->nodes / TWO_PI);
    Py_ssize_t cell = (Py_ssize_t)position;
    if (cell > md->nodes - 1)
        cell = md->nodes - 1;
    const Py_ssize_t next = cell + 1 == md->nodes ? 0 : cell + 1;
    const double t = position - (double)cell, t2 = t * t, t3 = t2 * t;
    const double spacing = TWO_PI / (double)md->nodes;
    hm->p0 = md->values + cell * md->fields;
    hm->p1 = md->values + next * md->fields;
    hm->d0 = md->slopes + cell * md->fields;
    hm->d1 = md->slopes + next * md->fields;
    hm->w00 = 2.0 * t3 - 3.0 * t2 + 1.0;
    hm->w10 = spacing * (t3 - 2.0 * t2 + t);
    hm->w01 = 3.0 * t2 - 2.0 * t3;
    hm->w11 = spacing * (t3 - t2);
}

/* count columns from col of one stage's Hermite cell into out (hv, vectorised). */
VECTOR_CLONES static void interpolate_one(const Hermite *hm, Py_ssize_t col, Py_ssize_t count,
                            double *restrict out)
{
    const double *restrict p0 = hm->p0 + col, *restrict p1 = hm->p1 + col,
                           *restrict d0 = hm->d0 + col, *restrict d1 = hm->d1 + col;
    const double w00 = hm->w00, w10 = hm->w10, w01 = hm->w01, w11 = hm->w11;
    for (Py_ssize_t j = 0; j < count; j++)
        out[j] = w00 * p0[j] + w10 * d0[j] + w01 * p1[j] + w11 * d1[j];
}

/*
 * Two stages whose cells share their nodes (the same cell, or b's first node is a's second):
 * one pass over the three or two nodes' rows. The rows are far larger than the caches, so
 * reading them is the cost.
 */
VECTOR_CLONES static void interpolate_pair(const Hermite *a, const Hermite *b, Py_ssize_t col,
                             Py_ssize_t count, double *restrict oa, double *restrict ob)
{
    const double *restrict p0 = a->p0 + col, *restrict p1 = a->p1 + col,
                           *restrict d0 = a->d0 + col, *restrict d1 = a->d1 + col;
    const double *restrict p2 = b->p1 + col, *restrict d2 = b->d1 + col;
    if (b->p0 == a->p0) {
        for (Py_ssize_t j = 0; j < count; j++) {
            const double x0 = p0[j], y0 = d0[j], x1 = p1[j], y1 = d1[j];
            oa[j] = a->w00 * x0 + a->w10 * y0 + a->w01 * x1 + a->w11 * y1;
            ob[j] = b->w00 * x0 + b->w10 * y0 + b->w01 * x1 + b->w11 * y1;
        }
        return;
    }
    for (Py_ssize_t j = 0; j < count; j++) {
        const double x1 = p1[j], y1 = d1[j];
        oa[j] = a->w00 * p0[j] + a->w10 * d0[j] + a->w01 * x1 + a->w11 * y1;
        ob[j] = b->w00 * x1 + b->w10 * y1 + b->w01 * p2[j] + b->w11 * d2[j];
    }
}

/* count columns from col of the tables at every stage into out (stage i at out + i stride). */
static void interpolate(const Hermite *hm, Py_ssize_t s, Py_ssize_t col, Py_ssize_t count,
                        double *out, Py_ssize_t stride)
{
    if (s == 2 && (hm[1].p0 == hm[0].p0 || hm[1].p0 == hm[0].p1)) {
        interpolate_pair(&hm[0], &hm[1], col, count, out, out + stride);
        return;
    }
    if (s == 2 && hm[0].p0 == hm[1].p1) {      /* the crank turning backwards */
        interpolate_pair(&hm[1], &hm[0], col, count, out + stride, out);
        return;
    }
    for (Py_ssize_t i = 0; i < s; i++)
        interpolate_one(&hm[i], col, count, out + i * stride);
}

/*
 * f_1 + a f_a + w^2 f_w2 of n entries per stage (w the stage's speed, a the acceleration):
 * written into out, or added to it (add != 0).
 */
static void speed_polynomial(const double *speed, double accel, Py_ssize_t s, Py_ssize_t n,
                             const double *f1, const double *fa, const double *fw2, int add,
                             double *out)
{
    for (Py_ssize_t i = 0; i < s; i++) {
        const double w2 = speed[i] * speed[i];
        for (Py_ssize_t j = i * n; j < (i + 1) * n; j++) {
            const double value = f1[j] + accel * fa[j] + w2 * fw2[j];
            out[j] = add ? out[j] + value : value;
        }
    }
}

/*
 * One stage's C and K from its interpolated G (in damping), K_el (in stiffness), K1, K_a and
 * K_w2: C = w G + beta (K_el + K_bear), K = K_el + K_bear + beta w K1 + a K_a + w^2 K_w2.
 */
VECTOR_CLONES static void stage_matrices(double w, double accel, double beta,
                                         const double *restrict bearing, Py_ssize_t mm,
                                         double *restrict damping, double *restrict stiffness,
                                         const double *restrict k1, const double *restrict ka,
                                         const double *restrict kw2)
{
    for (Py_ssize_t j = 0; j < mm; j++) {
        const double elastic = stiffness[j] + bearing[j];
        damping[j] = w * damping[j] + beta * elastic;
        stiffness[j] = elastic + beta * w * k1[j] + accel * ka[j] + w * w * kw2[j];
    }
}

/*
 * The linear part and the link tables at the stages into p (buf holds them), read from the
 * tables: C = w G + beta (K_el + K_bear), K = K_el + K_bear + beta w K1 + a K_a + w^2 K_w2
 * (+ K_G for the linear model), R = f_1 + a f_a + w^2 f_w2, as linear_part. raw: room for
 * three m x m and three m fields per stage.
 */
static void stage_tables(const Model *md, const double *angles, double accel, Problem *p,
                         double *buf, double *raw)
{
    const Py_ssize_t m = md->m, mm = m * m, e = md->e, s = md->s;
    double *mass = buf, *damping = mass + s * mm, *stiffness = damping + s * mm;
    double *load = stiffness + s * mm, *chord = load + s * m, *chord_rate = chord + s * e * m;
    double *shortening = chord_rate + s * e * m, *shortening_rate = shortening + s * e * mm;
    double *r1 = raw, *r2 = r1 + s * mm, *r3 = r2 + s * mm, *v1 = r3 + s * mm, *v2 = v1 + s * m,
           *v3 = v2 + s * m;
    Py_ssize_t o[FIELDS];
    for (Py_ssize_t k = 0; k < FIELDS; k++)
        o[k] = (Py_ssize_t)md->off[k];
    Hermite hm[3] = {0};
    for (Py_ssize_t i = 0; i < s; i++)
        hermite_at(md, angles[i], &hm[i]);
    interpolate(hm, s, o[0], mm, mass, mm);
    interpolate(hm, s, o[4], mm, stiffness, mm);            /* K_el, then K */
    interpolate(hm, s, o[1], mm, damping, mm);              /* G, then C */
    interpolate(hm, s, o[5], mm, r1, mm);
    interpolate(hm, s, o[2], mm, r2, mm);
    interpolate(hm, s, o[3], mm, r3, mm);
    for (Py_ssize_t i = 0; i < s; i++)
        stage_matrices(p->speed[i], accel, md->beta, md->bearing, mm, damping + i * mm,
                       stiffness + i * mm, r1 + i * mm, r2 + i * mm, r3 + i * mm);
    if (!md->nonlinear) {
        interpolate(hm, s, o[6], mm, r1, mm);
        interpolate(hm, s, o[7], mm, r2, mm);
        interpolate(hm, s, o[8], mm, r3, mm);
        speed_polynomial(p->speed, accel, s, mm, r1, r2, r3, 1, stiffness);
    }
    interpolate(hm, s, o[9], m, v1, m);
    interpolate(hm, s, o[10], m, v2, m);
    interpolate(hm, s, o[11], m, v3, m);
    speed_polynomial(p->speed, accel, s, m, v1, v2, v3, 0, load);
    interpolate(hm, s, o[12], e * m, chord, e * m);
    interpolate(hm, s, o[13], e * m, chord_rate, e * m);
    interpolate(hm, s, o[14], e * mm, shortening, e * mm);
    interpolate(hm, s, o[15], e * mm, shortening_rate, e * mm);
    p->mass = mass;
    p->damping = damping;
    p->stiffness = stiffness;
    p->load = load;
    p->chord = chord;
    p->chord_rate = chord_rate;
    p->shortening = shortening;
    p->shortening_rate = shortening_rate;
}

/* The output operator (outputs x m) at theta into out. */
static void output_at(const Model *md, double theta, double *out)
{
    Hermite hm;
    hermite_at(md, theta, &hm);
    interpolate_one(&hm, (Py_ssize_t)md->off[16], md->outputs * md->m, out);
}

/* x^T g x (g: m x m, row-major), summed in order (the link slopes' doubles as before). */
static double quadratic_form(const double *restrict g, const double *restrict x, Py_ssize_t m)
{
    double sum = 0.0;
    for (Py_ssize_t a = 0; a < m; a++) {
        const double *restrict row = g + a * m;
        double t = 0.0;
        for (Py_ssize_t b = 0; b < m; b++)
            t += row[b] * x[b];
        sum += x[a] * t;
    }
    return sum;
}

/* After a converged step: the new state, its output operator and link slopes. */
static void accept(const Model *md, State *st, const Problem *p, const Work *wk, double h)
{
    const Py_ssize_t s = md->s, m = md->m, e = md->e, last = s - 1;
    for (Py_ssize_t a = 0; a < m; a++) {
        double dq = 0.0, dv = 0.0;
        for (Py_ssize_t j = 0; j < s; j++) {
            dq += md->a2[last * s + j] * wk->acc[j * m + a];
            dv += md->a[last * s + j] * wk->acc[j * m + a];
        }
        st->q[a] = st->q[a] + h * st->v[a] + h * h * dq;
        st->v[a] = st->v[a] + h * dv;
    }
    memcpy(st->guess, wk->acc, (size_t)(s * m) * sizeof(double));
    st->guess[s * m] = h;
    st->has_guess = 1;
    memcpy(st->axial, wk->axial, (size_t)e * sizeof(double));
    output_at(md, wk->angles[last], st->output);
    /* RMS slope of each link's bending: sqrt(2 S_L / L), S_L = q^T g_L q / 2 */
    for (Py_ssize_t l = 0; l < e; l++) {
        const double doubled = quadratic_form(p->shortening + (last * e + l) * m * m, st->q, m);
        st->slope[l] = sqrt(fmax(doubled, 0.0) / md->length[l]);
    }
}

/*
 * The Newton start: the last step's stage accelerations extrapolated linearly in time from its
 * last two stages to this step's stage times (guess[s m] holds that step's h); zero without.
 */
static void predict(const Model *md, const State *st, double h, double *acc)
{
    const Py_ssize_t s = md->s, m = md->m;
    if (!st->has_guess) {
        memset(acc, 0, (size_t)(s * m) * sizeof(double));
        return;
    }
    const double *last = st->guess + (s - 1) * m, *before = st->guess + (s > 1 ? s - 2 : 0) * m;
    const double span = s > 1 ? (md->c[s - 1] - md->c[s - 2]) * st->guess[s * m] : 1.0;
    for (Py_ssize_t i = 0; i < s; i++) {
        const double t = s > 1 ? md->c[i] * h / span : 0.0;
        for (Py_ssize_t a = 0; a < m; a++)
            acc[i * m + a] = last[a] + t * (last[a] - before[a]);
    }
}

/*
 * One step of length h between two samples (angle, speed linear between them); a step whose
 * Newton fails is retried as two halves, at most `halvings` times deep. Returns 0 if it
 * failed (the state is then as before), else a positive count.
 */
static Py_ssize_t advance(const Model *md, State *st, Work *wk, double h, double th0,
                          double th1, double w0, double w1, int halvings)
{
    if (!(isfinite(h) && isfinite(th0) && isfinite(th1) && isfinite(w0) && isfinite(w1)
          && h > 0.0))
        return 0;
    const Py_ssize_t s = md->s, m = md->m;
    Problem p;
    for (Py_ssize_t i = 0; i < s; i++) {
        wk->angles[i] = th0 + md->c[i] * (th1 - th0);
        wk->speed[i] = w0 + md->c[i] * (w1 - w0);
    }
    p.speed = wk->speed;
    p.q = st->q;
    p.v = st->v;
    p.a = md->a;
    p.a2 = md->a2;
    p.c = md->c;
    p.k = md->k;
    p.acc = wk->acc;
    p.axial = wk->axial;
    p.s = s;
    p.m = m;
    p.e = md->e;
    p.h = h;
    p.beta = md->beta;
    p.nonlinear = md->nonlinear;
    stage_tables(md, wk->angles, (w1 - w0) / h, &p, wk->tables, wk->raw);
    predict(md, st, h, wk->acc);
    wk->factor.valid = 0;
    Py_ssize_t count = solve(&p, md->tolerance, md->divergence, md->iterations, wk->mem,
                             &wk->factor);
    for (Py_ssize_t i = 0; count > 0 && i < s * m; i++)
        if (!isfinite(wk->acc[i]))
            count = 0;
    if (count > 0) {
        st->iterations += count;
        accept(md, st, &p, wk, h);
        return count;
    }
    if (halvings == 0)
        return 0;
    const size_t saved_size = (size_t)(2 * m + s * m + 1);
    double *saved = malloc(saved_size * sizeof(double));
    if (saved == NULL)
        return 0;
    memcpy(saved, st->q, (size_t)m * sizeof(double));
    memcpy(saved + m, st->v, (size_t)m * sizeof(double));
    memcpy(saved + 2 * m, st->guess, (size_t)(s * m + 1) * sizeof(double));
    const int had_guess = st->has_guess;
    const double th_mid = 0.5 * (th0 + th1), w_mid = 0.5 * (w0 + w1);
    st->has_guess = 0;
    const int ok = advance(md, st, wk, 0.5 * h, th0, th_mid, w0, w_mid, halvings - 1) > 0
                   && advance(md, st, wk, 0.5 * h, th_mid, th1, w_mid, w1, halvings - 1) > 0;
    if (!ok) {
        memcpy(st->q, saved, (size_t)m * sizeof(double));
        memcpy(st->v, saved + m, (size_t)m * sizeof(double));
        memcpy(st->guess, saved + 2 * m, (size_t)(s * m + 1) * sizeof(double));
        st->has_guess = had_guess;
    }
    free(saved);
    return ok;
}

static double now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

/* Step through samples 1..K; per sample its outputs, axial forces, slopes, flag, time. */
static void march_samples(const Model *md, State *st, Work *wk, const double *times,
                          const double *angles, const double *speeds, Py_ssize_t samples,
                          int halvings, double *outputs, double *axial, double *slope,
                          double *converged, double *update_ns)
{
    const Py_ssize_t m = md->m, e = md->e, n_out = md->outputs;
    for (Py_ssize_t k = 1; k <= samples; k++) {
        const double begin = now_ns();
        const int ok = advance(md, st, wk, times[k] - times[k - 1], angles[k - 1], angles[k],
                               speeds[k - 1], speeds[k], halvings) > 0;
        if (!ok && isfinite(angles[k]))
            output_at(md, angles[k], st->output);
        double *out = outputs + (k - 1) * n_out;
        for (Py_ssize_t o = 0; o < n_out; o++) {
            double t = 0.0;
            for (Py_ssize_t a = 0; a < m; a++)
                t += st->output[o * m + a] * st->q[a];
            out[o] = t;
        }
        memcpy(axial + (k - 1) * e, st->axial, (size_t)e * sizeof(double));
        memcpy(slope + (k - 1) * e, st->slope, (size_t)e * sizeof(double));
        converged[k - 1] = ok;
        update_ns[k - 1] = now_ns() - begin;
    }
}

/*
 * march(values, slopes, offsets, bearing, axial_stiffness, link_length, a, a2, c,
 *       times, angles, speeds, q, v, guess, axial, slope, output,
 *       outputs, axial_out, slope_out, converged, update_ns, work,
 *       nodes, fields, stages, size, links, channels, samples, beta, nonlinear, tolerance,
 *       iterations, divergence, halvings, has_guess) -> (newton iterations, has_guess)
 *
 * Steps the state (q, v, guess, axial, slope, output: written in place) from sample 0 through
 * `samples` more samples (times [s], unwrapped angles, speeds: samples + 1 each), reading the
 * tables (values, slopes: nodes x fields, NonlinearTables) at the stage angles by cubic
 * Hermite interpolation. Per sample: outputs (channels), axial_out and slope_out (links),
 * converged (1.0 / 0.0) and update_ns (the step's own time). A step that does not converge
 * keeps the state, and its output operator is then the one at the sample's angle.
 * work: scratch of workspace(stages, size, links, channels) doubles, made once by the caller.
 */
#define MARCH_ARGS 38
#define BUFFERS 24

static int march_sizes(Model *md, Py_ssize_t *samples, int *halvings, int *has_guess,
                       PyObject *const *args)
{
    md->nodes = PyLong_AsSsize_t(args[24]);
    md->fields = PyLong_AsSsize_t(args[25]);
    md->s = PyLong_AsSsize_t(args[26]);
    md->m = PyLong_AsSsize_t(args[27]);
    md->e = PyLong_AsSsize_t(args[28]);
    md->outputs = PyLong_AsSsize_t(args[29]);
    *samples = PyLong_AsSsize_t(args[30]);
    md->beta = PyFloat_AsDouble(args[31]);
    md->nonlinear = PyObject_IsTrue(args[32]);
    md->tolerance = PyFloat_AsDouble(args[33]);
    md->iterations = PyLong_AsSsize_t(args[34]);
    md->divergence = PyFloat_AsDouble(args[35]);
    *halvings = (int)PyLong_AsLong(args[36]);
    *has_guess = PyObject_IsTrue(args[37]);
    if (PyErr_Occurred())
        return -1;
    if (md->s < 1 || md->s > 3 || md->m < 1 || md->m > 512 || md->e < 0 || md->e > 64
        || md->outputs < 0 || md->outputs > 64 || md->nodes < 2 || md->fields < 1
        || *samples < 0 || *halvings < 0 || *halvings > 20 || md->iterations < 1
        || !(md->divergence > 1.0)) {
        PyErr_SetString(PyExc_ValueError, "march: sizes or Newton limits out of range");
        return -1;
    }
    return 0;
}

/* Every field's offset and extent inside the flat row; -1 with an exception if not. */
static int check_offsets(const Model *md)
{
    const Py_ssize_t m = md->m, mm = m * m, e = md->e;
    const Py_ssize_t extent[FIELDS] = {mm, mm, mm, mm, mm, mm, mm, mm, mm, m, m, m, e * m, e * m,
                                       e * mm, e * mm, md->outputs * m};
    for (Py_ssize_t k = 0; k < FIELDS; k++) {
        const double o = md->off[k];
        if (!(o >= 0.0 && o == floor(o) && o + (double)extent[k] <= (double)md->fields)) {
            PyErr_SetString(PyExc_ValueError, "march: a field lies outside the table's row");
            return -1;
        }
    }
    return 0;
}

/* Doubles of march's workspace: the stage tables, Newton's arrays, the LU and the rest. */
static Py_ssize_t workspace_doubles(Py_ssize_t s, Py_ssize_t m, Py_ssize_t e, Py_ssize_t outputs)
{
    const Py_ssize_t n = s * m, mm = m * m;
    return (3 * s * mm + s * m + 2 * s * e * m + 2 * s * e * mm) + (3 * n + 2 * s * mm + 4 * m)
           + (n * n + n + s * m + 2 * s + e + outputs * m) + 3 * s * (mm + m) + n * n;
}

/* The workspace's parts inside the work buffer (views[23]) and the state's arrays. */
static void work_of(const Model *md, Py_buffer *views, int has_guess, Work *wk, State *st)
{
    const Py_ssize_t s = md->s, m = md->m, e = md->e, n = s * m, mm = m * m;
    const Py_ssize_t tables = 3 * s * mm + s * m + 2 * s * e * m + 2 * s * e * mm;
    const Py_ssize_t mem = 3 * n + 2 * s * mm + 4 * m;
    double *buf = views[23].buf;
    /* the pivots, as Py_ssize_t in doubles' room (both 8 bytes here, checked at import) */
    *wk = (Work){buf, buf + tables, buf + tables + mem + n * n + n, NULL, NULL, NULL, NULL, NULL,
                 {buf + tables + mem, NULL, (Py_ssize_t *)(buf + tables + mem + n * n), 0}};
    wk->angles = wk->acc + s * m;
    wk->speed = wk->angles + s;
    wk->axial = wk->speed + s;
    wk->output = wk->axial + e;
    wk->raw = wk->output + md->outputs * m;
    wk->factor.lut = wk->raw + 3 * s * (mm + m);
    *st = (State){views[12].buf, views[13].buf, views[14].buf, views[15].buf, views[16].buf,
                  views[17].buf, has_guess, 0};
}

/*
 * Take march's arguments: the sizes and constants into md (and samples, halvings, has_guess),
 * the BUFFERS buffers into views. Returns 0, or -1 with an exception set and none taken.
 */
static int take_arguments(PyObject *const *args, Model *md, Py_ssize_t *samples, int *halvings,
                          int *has_guess, Py_buffer *views)
{
    if (march_sizes(md, samples, halvings, has_guess, args) < 0)
        return -1;
    const Py_ssize_t s = md->s, m = md->m, e = md->e, k = *samples, p = md->outputs;
    const Py_ssize_t counts[BUFFERS] = {md->nodes * md->fields, md->nodes * md->fields, FIELDS,
                                        m * m, e, e, s * s, s * s, s, k + 1, k + 1, k + 1, m, m,
                                        s * m + 1, e, e, p * m, k * p, k * e, k * e, k, k,
                                        workspace_doubles(s, m, e, p)};
    static const char *const names[BUFFERS] = {
        "values", "slopes", "offsets", "bearing", "axial_stiffness", "link_length", "a", "a2",
        "c", "times", "angles", "speeds", "q", "v", "guess", "axial", "slope", "output",
        "outputs", "axial_out", "slope_out", "converged", "update_ns", "work"};
    Py_ssize_t taken = 0;
    for (; taken < BUFFERS; taken++)
        if (get_doubles(args[taken], &views[taken], counts[taken], names[taken], taken >= 12)
            < 0)
            break;
    if (taken == BUFFERS) {
        md->values = views[0].buf;
        md->slopes = views[1].buf;
        md->off = views[2].buf;
        md->bearing = views[3].buf;
        md->k = views[4].buf;
        md->length = views[5].buf;
        md->a = views[6].buf;
        md->a2 = views[7].buf;
        md->c = views[8].buf;
        if (check_offsets(md) == 0)
            return 0;
    }
    for (Py_ssize_t i = 0; i < taken; i++)
        PyBuffer_Release(&views[i]);
    return -1;
}

static PyObject *march(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != MARCH_ARGS) {
        PyErr_SetString(PyExc_TypeError, "march takes 38 arguments (see the module notes)");
        return NULL;
    }
    Model md;
    Py_ssize_t samples;
    int halvings, has_guess;
    Py_buffer views[BUFFERS];
    if (take_arguments(args, &md, &samples, &halvings, &has_guess, views) < 0)
        return NULL;
    Work wk;
    State st;
    work_of(&md, views, has_guess, &wk, &st);
    Py_BEGIN_ALLOW_THREADS
    march_samples(&md, &st, &wk, views[9].buf, views[10].buf, views[11].buf, samples, halvings,
                  views[18].buf, views[19].buf, views[20].buf, views[21].buf, views[22].buf);
    Py_END_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < BUFFERS; i++)
        PyBuffer_Release(&views[i]);
    return Py_BuildValue("(ni)", st.iterations, st.has_guess);
}

/*
 * Stepper(*march's 38 arguments, samples 1): one estimator's per-sample step (the node's
 * streaming update), its buffers taken once. step(h, theta0, angle, speed0, speed, has_guess,
 * halvings, unwrap) steps the state as march steps one sample (times 0, h; angles theta0 and
 * theta), theta the angle unwrapped from theta0 by the speeds (unwrap_next of
 * nonlinear_stream.py, the same arithmetic) if unwrap, else the angle as given. Returns
 * (theta, iterations, has_guess, converged), or None where the unwrapping is not finite (the
 * Python path then says why) with nothing changed.
 */
typedef struct {
    PyObject_HEAD
    Model md;
    Py_buffer views[BUFFERS];
    int holds;
} Stepper;

static int stepper_init(Stepper *self, PyObject *args, PyObject *kwargs)
{
    if (kwargs != NULL && PyDict_GET_SIZE(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "Stepper takes march's arguments by position");
        return -1;
    }
    if (self->holds) {
        PyErr_SetString(PyExc_TypeError, "Stepper is made once");
        return -1;
    }
    if (PyTuple_GET_SIZE(args) != MARCH_ARGS) {
        PyErr_SetString(PyExc_TypeError, "Stepper takes march's 38 arguments");
        return -1;
    }
    Py_ssize_t samples;
    int halvings, has_guess;
    if (take_arguments(&PyTuple_GET_ITEM(args, 0), &self->md, &samples, &halvings, &has_guess,
                       self->views) < 0)
        return -1;
    self->holds = 1;
    if (samples != 1) {
        PyErr_SetString(PyExc_ValueError, "Stepper steps one sample (samples 1)");
        return -1;
    }
    return 0;
}

static void stepper_dealloc(Stepper *self)
{
    if (self->holds)
        for (Py_ssize_t i = 0; i < BUFFERS; i++)
            PyBuffer_Release(&self->views[i]);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *stepper_step(Stepper *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!self->holds) {
        PyErr_SetString(PyExc_ValueError, "Stepper not made");
        return NULL;
    }
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError,
                        "step(h, theta0, angle, speed0, speed, has_guess, halvings, unwrap)");
        return NULL;
    }
    double x[5];
    for (int i = 0; i < 5; i++)
        x[i] = PyFloat_AsDouble(args[i]);
    const int has_guess = PyObject_IsTrue(args[5]);
    const long halvings = PyLong_AsLong(args[6]);
    const int unwrap = PyObject_IsTrue(args[7]);
    if (PyErr_Occurred())
        return NULL;
    if (halvings < 0 || halvings > 20) {
        PyErr_SetString(PyExc_ValueError, "step: halvings out of range");
        return NULL;
    }
    const double h = x[0], theta0 = x[1], angle = x[2], speed0 = x[3], speed = x[4];
    /* unwrap_next, operation for operation (np.pi; round: to nearest, ties to even) */
    const double two_pi = 2.0 * 3.141592653589793;
    const double predicted = 0.5 * (speed + speed0) * h;
    const double change = (angle - theta0) - predicted;
    const double turns = change / two_pi;
    if (unwrap && !isfinite(turns))
        Py_RETURN_NONE;
    const double theta = unwrap ? theta0 + (predicted + change - two_pi * nearbyint(turns))
                                : angle;
    Py_buffer *views = self->views;
    double *times = views[9].buf, *angles = views[10].buf, *speeds = views[11].buf;
    times[0] = 0.0;
    times[1] = h;
    angles[0] = theta0;
    angles[1] = theta;
    speeds[0] = speed0;
    speeds[1] = speed;
    Work wk;
    State st;
    work_of(&self->md, views, has_guess, &wk, &st);
    Py_BEGIN_ALLOW_THREADS
    march_samples(&self->md, &st, &wk, times, angles, speeds, 1, (int)halvings, views[18].buf,
                  views[19].buf, views[20].buf, views[21].buf, views[22].buf);
    Py_END_ALLOW_THREADS
    const int converged = ((double *)views[21].buf)[0] != 0.0;
    return Py_BuildValue("(dnii)", theta, st.iterations, st.has_guess, converged);
}

static PyMethodDef STEPPER_METHODS[] = {
    {"step", (PyCFunction)(void (*)(void))stepper_step, METH_FASTCALL,
     "Unwrap one sample's angle and step the state to it (see the notes)."},
    {NULL, NULL, 0, NULL}};

static PyTypeObject STEPPER_TYPE = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "flexlink_ros.core.estimation._nonlinear_step."
                                             "Stepper",
    .tp_basicsize = sizeof(Stepper),
    .tp_dealloc = (destructor)stepper_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "One estimator's per-sample step, its buffers taken once (see the notes).",
    .tp_methods = STEPPER_METHODS,
    .tp_init = (initproc)stepper_init,
    .tp_new = PyType_GenericNew,
};

static PyObject *workspace(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "workspace(stages, size, links, channels)");
        return NULL;
    }
    Py_ssize_t v[4];
    for (int i = 0; i < 4; i++)
        v[i] = PyLong_AsSsize_t(args[i]);
    if (PyErr_Occurred())
        return NULL;
    if (v[0] < 1 || v[0] > 3 || v[1] < 1 || v[1] > 512 || v[2] < 0 || v[2] > 64 || v[3] < 0
        || v[3] > 64) {
        PyErr_SetString(PyExc_ValueError, "workspace: sizes out of range");
        return NULL;
    }
    return PyLong_FromSsize_t(workspace_doubles(v[0], v[1], v[2], v[3]));
}

static PyMethodDef METHODS[] = {
    {"workspace", (PyCFunction)(void (*)(void))workspace, METH_FASTCALL,
     "Doubles of march's scratch buffer for (stages, size, links, channels)."},
    {"march", (PyCFunction)(void (*)(void))march, METH_FASTCALL,
     "Step the reduced nonlinear model through samples, reading its tables (see the notes)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef MODULE = {PyModuleDef_HEAD_INIT, "_nonlinear_step",
                                    "The reduced nonlinear model's step (C).", -1, METHODS};

PyMODINIT_FUNC PyInit__nonlinear_step(void)
{
    /* march keeps the LU's pivots in its float64 scratch */
    if (sizeof(Py_ssize_t) > sizeof(double)) {
        PyErr_SetString(PyExc_ImportError, "_nonlinear_step: Py_ssize_t wider than double");
        return NULL;
    }
    if (PyType_Ready(&STEPPER_TYPE) < 0)
        return NULL;
    PyObject *module = PyModule_Create(&MODULE);
    if (module == NULL)
        return NULL;
    Py_INCREF(&STEPPER_TYPE);
    if (PyModule_AddObject(module, "Stepper", (PyObject *)&STEPPER_TYPE) < 0) {
        Py_DECREF(&STEPPER_TYPE);
        Py_DECREF(module);
        return NULL;
    }
    return module;
}
