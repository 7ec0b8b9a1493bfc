/*
 * The per-sample loads of the dynamic second-order pass, compiled: the form of
 * flexlink_ros/core/estimation/second_order_dynamic_kernel.py (DynamicPassKernel, whose numpy
 * path is its twin and reference; a test compares the two). Plain C API, no numpy headers.
 *
 * loads(context, pieces, unit, scalars, stored, states, out, angle_stage, angle_sample,
 *       stage_slot, sample_slot) -> None
 *
 *   context  float64 buffer: r, D (gather rows), L (links), N (grid cells), S (spline scalars
 *            per cell power), then per link (first row, elements) and (element length, EA).
 *   pieces   float64 (3, D, r): B0, Bc, Bs of all links (dynamic_pieces).
 *   unit     float64 (L, 6, 6): the unit geometric stiffness of each link's elements.
 *   scalars  float64 (N, 4, S): the periodic spline of cos, sin of each link angle first.
 *   stored   float64 (2, 4, r r): the step's [M, C, K, F] of stage 1 and of the sample, in
 *            alternating slots (core/estimation/step.py).
 *   states   float64 (2, r): the linear q at stage 1 and at the sample.
 *   out      float64 (3, r), written: f2 at stage 1, f2 at the sample, and
 *            K_r^-1 f2_eigenstrain at the sample.
 *
 * Per point: s = K_r^-1 f_r (the reduced static response; its elastic axial force is the
 * reference of the linear state's), per link the gather B = B0 + cos Bc + sin Bs, u = B q,
 * per element the eigenstrain load EA (1/2 u^T G u) / l [1, 0, 0, -1, 0, 0] and the
 * geometric-stiffness load -N_e G u with N_e = EA ((u_4 - u_1) - (s_4 - s_1)) / l, f2 = B^T f
 * (core/reduction/second_order_dynamic_tables.py, element_loads).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "_doubles.h"

#define TWO_PI 6.283185307179586
#define MAX_SIZE 64
#define MAX_LINKS 8
#define MAX_ROWS 512
enum { C_SIZE, C_ROWS, C_LINKS, C_GRID, C_SCALARS, C_HEADER };

/* Solve a x = b (n x n, row-major, copied; x may be b) by Gaussian elimination with partial
   pivoting. */
static int solve(int n, const double *matrix, const double *b, double *x)
{
    static double a[4 * MAX_SIZE * MAX_SIZE];     /* n <= 2 MAX_SIZE; the GIL is held */
    memcpy(a, matrix, sizeof(double) * n * n);
    if (x != b)
        memcpy(x, b, sizeof(double) * n);
    for (int k = 0; k < n; k++) {
        int p = k;
        for (int i = k + 1; i < n; i++)
            if (fabs(a[i * n + k]) > fabs(a[p * n + k]))
                p = i;
        if (a[p * n + k] == 0.0)
            return -1;
        if (p != k) {
            for (int j = 0; j < n; j++) {
                double t = a[k * n + j];
                a[k * n + j] = a[p * n + j];
                a[p * n + j] = t;
            }
            double t = x[k];
            x[k] = x[p];
            x[p] = t;
        }
        for (int i = k + 1; i < n; i++) {
            double f = a[i * n + k] / a[k * n + k];
            for (int j = k + 1; j < n; j++)
                a[i * n + j] -= f * a[k * n + j];
            x[i] -= f * x[k];
        }
    }
    for (int i = n - 1; i >= 0; i--) {
        double acc = x[i];
        for (int j = i + 1; j < n; j++)
            acc -= a[i * n + j] * x[j];
        x[i] = acc / a[i * n + i];
    }
    return 0;
}

/* cos, sin of each link angle from the spline at a crank angle. */
static void link_trig(const double *context, const double *scalars, double angle, double *trig)
{
    const int grid = (int)context[C_GRID], width = (int)context[C_SCALARS];
    const int links = (int)context[C_LINKS];
    double x = fmod(angle, TWO_PI);
    if (x < 0.0)
        x += TWO_PI;
    x *= grid / TWO_PI;
    int k = (int)x;
    if (k > grid - 1)
        k = grid - 1;
    const double t = x - k, powers[4] = {1.0, t, t * t, t * t * t};
    const double *cell = scalars + (Py_ssize_t)k * 4 * width;
    for (int i = 0; i < 2 * links; i++) {
        double acc = 0.0;
        for (int p = 0; p < 4; p++)
            acc += powers[p] * cell[p * width + i];
        trig[i] = acc;
    }
}

/* f2 (total, eigenstrain part) of q against the static state s at one crank angle. */
static void point_load(const double *context, const double *pieces, const double *unit,
                       const double *trig, const double *q, const double *s, double *total,
                       double *eigen)
{
    const int r = (int)context[C_SIZE], rows_all = (int)context[C_ROWS];
    const int links = (int)context[C_LINKS];
    const double *info = context + C_HEADER, *values = info + 2 * links;
    static double gather[MAX_ROWS * MAX_SIZE];
    double local[MAX_ROWS], stat[MAX_ROWS], load[MAX_ROWS], part[MAX_ROWS];
    memset(total, 0, sizeof(double) * r);
    memset(eigen, 0, sizeof(double) * r);
    for (int n = 0; n < links; n++) {
        const int first = (int)info[2 * n], elements = (int)info[2 * n + 1];
        const int rows = 3 * (elements + 1);
        const double c = trig[2 * n], sn = trig[2 * n + 1];
        const double length = values[2 * n], ea = values[2 * n + 1];
        const double *p0 = pieces + (Py_ssize_t)first * r, *pc = p0 + (Py_ssize_t)rows_all * r;
        const double *ps = pc + (Py_ssize_t)rows_all * r, *g = unit + 36 * n;
        for (int a = 0; a < rows * r; a++)
            gather[a] = p0[a] + c * pc[a] + sn * ps[a];
        for (int a = 0; a < rows; a++) {
            double x = 0.0, y = 0.0;
            for (int k = 0; k < r; k++) {
                x += gather[a * r + k] * q[k];
                y += gather[a * r + k] * s[k];
            }
            local[a] = x;
            stat[a] = y;
            load[a] = part[a] = 0.0;
        }
        for (int e = 0; e < elements; e++) {
            const double *u = local + 3 * e;
            double gu[6], shortening = 0.0;
            for (int i = 0; i < 6; i++) {
                double acc = 0.0;
                for (int j = 0; j < 6; j++)
                    acc += g[6 * i + j] * u[j];
                gu[i] = acc;
                shortening += acc * u[i];
            }
            const double pull = 0.5 * ea * shortening / length;
            const double axial = ea / length * ((u[3] - u[0]) - (stat[3 * e + 3] - stat[3 * e]));
            for (int i = 0; i < 6; i++)
                load[3 * e + i] -= axial * gu[i];
            load[3 * e] += pull;
            load[3 * e + 3] -= pull;
            part[3 * e] += pull;
            part[3 * e + 3] -= pull;
        }
        for (int a = 0; a < rows; a++)
            for (int k = 0; k < r; k++) {
                total[k] += load[a] * gather[a * r + k];
                eigen[k] += part[a] * gather[a * r + k];
            }
    }
}

/* Check the context's sizes and that every link's gather rows fit. */
static int check_context(const double *context, Py_ssize_t length)
{
    const int r = (int)context[C_SIZE], rows = (int)context[C_ROWS];
    const int links = (int)context[C_LINKS];
    if (r < 1 || r > MAX_SIZE || links < 1 || links > MAX_LINKS || context[C_GRID] < 1
        || context[C_SCALARS] < 2 * links || length < C_HEADER + 4 * links)
        return -1;
    for (int n = 0; n < links; n++) {
        const int first = (int)context[C_HEADER + 2 * n];
        const int count = 3 * ((int)context[C_HEADER + 2 * n + 1] + 1);
        if (first < 0 || count > MAX_ROWS || first + count > rows)
            return -1;
    }
    return 0;
}

static PyObject *loads(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 11) {
        PyErr_SetString(PyExc_TypeError, "loads(context, pieces, unit, scalars, stored, states, "
                        "out, angle_stage, angle_sample, stage_slot, sample_slot)");
        return NULL;
    }
    const double angles[2] = {PyFloat_AsDouble(args[7]), PyFloat_AsDouble(args[8])};
    const long slots[2] = {PyLong_AsLong(args[9]), PyLong_AsLong(args[10])};
    if (PyErr_Occurred())
        return NULL;
    Py_buffer views[7];
    int held = 0;
    PyObject *result = NULL;
    if (get_doubles(args[0], &views[0], C_HEADER, "context", 0) < 0)
        return NULL;
    held = 1;
    const double *context = views[0].buf;
    const Py_ssize_t length = views[0].len / (Py_ssize_t)sizeof(double);
    if (check_context(context, length) < 0) {
        PyErr_SetString(PyExc_ValueError, "context: bad sizes");
        goto release;
    }
    const Py_ssize_t r = (Py_ssize_t)context[C_SIZE], rows = (Py_ssize_t)context[C_ROWS];
    const Py_ssize_t counts[7] = {C_HEADER, 3 * rows * r, 36 * (Py_ssize_t)context[C_LINKS],
                                  (Py_ssize_t)context[C_GRID] * 4 * (Py_ssize_t)context[C_SCALARS],
                                  8 * r * r, 2 * r, 3 * r};
    static const char *names[7] = {"context", "pieces", "unit", "scalars", "stored", "states",
                                   "out"};
    for (; held < 7; held++)
        if (get_doubles(args[held], &views[held], counts[held], names[held], held == 6) < 0)
            goto release;
    if (slots[0] < 0 || slots[0] > 1 || slots[1] < 0 || slots[1] > 1) {
        PyErr_SetString(PyExc_ValueError, "slots must be 0 or 1");
        goto release;
    }
    const double *stored = views[4].buf, *states = views[5].buf;
    double *out = views[6].buf, eigen[MAX_SIZE], total[MAX_SIZE], statics[MAX_SIZE];
    double trig[2 * MAX_LINKS];
    for (int point = 0; point < 2; point++) {
        const double *slot = stored + slots[point] * 4 * r * r;
        if (solve((int)r, slot + 2 * r * r, slot + 3 * r * r, statics) < 0) {
            PyErr_SetString(PyExc_ValueError, "singular reduced stiffness");
            goto release;
        }
        link_trig(context, views[3].buf, angles[point], trig);
        point_load(context, views[1].buf, views[2].buf, trig, states + point * r, statics,
                   total, eigen);
        memcpy(out + point * r, total, sizeof(double) * r);
    }
    if (solve((int)r, stored + slots[1] * 4 * r * r + 2 * r * r, eigen, out + 2 * r) < 0) {
        PyErr_SetString(PyExc_ValueError, "singular reduced stiffness");
        goto release;
    }
    result = Py_None;
    Py_INCREF(result);
release:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

/* ---- The second state's Radau IIA step beside the compiled linear step ----------------
 *
 * advance(loads_context, pieces, unit, scalars, step_context, mass, damping, kf, g0, out,
 *         rows, z_start, previous, states, z2, static2, increments) -> None
 *
 *   step_context float64: r, grid, cells per radian, mass groups, kf groups, out rows, c_1,
 *            g_1, g_2 (second_order_dynamic_step.STAGE_WEIGHTS), first group of M and C, groups
 *            of C (STEP_*).
 *   mass, damping float32 (grid, 2 groups, r r); kf float64 (grid, 2 groups, r r + r): the
 *            step tables' node data (core/estimation/tables.py); g0 float64 (5, 64): G(h),
 *            the sample in slot 0 and stage 1 in slot 1; out float64 (grid, out rows,
 *            4 (r + 1)): the power-form output operator.
 *   rows     float64 (n, 6): steps without sub-steps (h, 1, angle, speed, accel, advance).
 *   z_start  float64 (2 r): the linear (q, v) before the first row; previous (3): its crank
 *            state; states float64 (n, 2 r): the linear (q, v) after each row (the compiled
 *            linear step's).
 *   z2, static2 float64 (2 r), (r): the second state and K_r^-1 f2_eigenstrain, advanced in
 *            place; increments float64 (n, 4), written: the outputs' increment
 *            O (q2 - K_r^-1 f2_eigenstrain) after each row.
 *
 * Per row the numpy twin's (DynamicSecondOrderStep._step) arithmetic: M, C, [K | f] at stage
 * 1 and at the sample from the node tables, the 2 r block system of G(h) (the linear step's,
 * factored here again), the stage-1 linear q from the step's increment, the loads (loads()),
 * and the increment of z2.
 */
enum {
    STEP_SIZE, STEP_GRID, STEP_CELLS, STEP_MASS_GROUPS, STEP_KF_GROUPS, STEP_OUT_ROWS,
    STEP_C1, STEP_G1, STEP_G2, STEP_FIRST_MC, STEP_GROUPS_C, STEP_HEADER
};
#define MONOMIAL_COUNT 7

typedef struct {
    int r, grid, mass_groups, kf_groups, out_rows, first_mc, groups_c;
    double cells;
    const float *mass, *damping;
    const double *kf, *out;
} StepTables;

static int cell_of(const StepTables *st, double angle, double *t)
{
    double x = angle * st->cells;
    int k = (int)x;
    if (k >= st->grid)
        k = st->grid - 1;
    if (k < 0)
        k = 0;
    *t = x - k;
    return k;
}

/* Monomials a, 1, w2, w, w4, wa, w3 (core/reduction/cells.py MONOMIALS). */
static void monomials(double w, double a, double *m)
{
    const double w2 = w * w;
    m[0] = a; m[1] = 1.0; m[2] = w2; m[3] = w; m[4] = w2 * w2; m[5] = w * a; m[6] = w2 * w;
}

/*
 * One node table at (cell k, t): sum over groups of Hermite weights times value and slope
 * (mono: the groups' monomial values, from the table's first group on).
 */
#define DEFINE_COMBINE(name, type)                                                          \
    static void name(const type *table, int grid, int groups, int width, const double *mono, \
                     int k, double t, double *out)                                          \
    {                                                                                       \
        const double t2 = t * t, t3 = t2 * t, h01 = t2 * (3.0 - 2.0 * t);                   \
        const double weights[2][2] = {{1.0 - h01, t - 2.0 * t2 + t3}, {h01, t3 - t2}};      \
        const int nodes[2] = {k, k + 1 < grid ? k + 1 : 0};                                 \
        for (int i = 0; i < width; i++)                                                     \
            out[i] = 0.0;                                                                   \
        for (int n = 0; n < 2; n++)                                                         \
            for (int g = 0; g < groups; g++)                                                \
                for (int j = 0; j < 2; j++) {                                               \
                    const double c = mono[g] * weights[n][j];                               \
                    const type *row = table + ((Py_ssize_t)nodes[n] * 2 * groups + 2 * g + j) \
                                              * width;                                      \
                    for (int i = 0; i < width; i++)                                         \
                        out[i] += c * row[i];                                               \
                }                                                                           \
    }

DEFINE_COMBINE(combine_float, float)
DEFINE_COMBINE(combine_double, double)

/* [M, C, K, f] at a crank state into a slot (M, C, K: r r each, then f: r). */
static void load_slot(const StepTables *st, double angle, double w, double a, double *slot)
{
    const int r = st->r, r2 = r * r;
    double mono[MONOMIAL_COUNT], t;
    monomials(w, a, mono);
    const int k = cell_of(st, angle, &t);
    combine_float(st->mass, st->grid, st->mass_groups, r2, mono + st->first_mc, k, t, slot);
    combine_float(st->damping, st->grid, st->groups_c, r2, mono + st->first_mc, k, t,
                  slot + r2);
    combine_double(st->kf, st->grid, st->kf_groups, r2 + r, mono, k, t, slot + 2 * r2);
}

/* The output operator O (4 x r) at a crank state times x, into out (4). */
static void output_increment(const StepTables *st, double angle, double w, double a,
                             const double *x, double *out)
{
    const int r = st->r, width = 4 * (r + 1);
    double mono[MONOMIAL_COUNT], t;
    monomials(w, a, mono);
    const int k = cell_of(st, angle, &t);
    const double powers[4] = {1.0, t, t * t, t * t * t};
    const double *cell = st->out + (Py_ssize_t)k * st->out_rows * width;
    for (int o = 0; o < 4; o++)
        out[o] = 0.0;
    for (int row = 0; row < st->out_rows; row++) {
        const double c = mono[row / 4] * powers[row % 4];
        if (c == 0.0)
            continue;
        for (int o = 0; o < 4; o++) {
            double acc = 0.0;
            for (int i = 0; i < r; i++)
                acc += cell[row * width + o * (r + 1) + i] * x[i];
            out[o] += c * acc;
        }
    }
}

/* The 2 r system and right-hand side of one step: A dz2 = op(z2) + (f2 stage, f2 sample). */
static int second_increment(int r, const double *g0, double h, const double *slots,
                            const double *z2, const double *loads, double *system, double *dz)
{
    const int r2 = r * r, n = 2 * r, slot_size = 3 * r2 + r;
    const double hp[5] = {1.0 / (h * h), 1.0 / h, 1.0, h, h * h};
    double g[64];
    for (int e = 0; e < 64; e++) {
        double acc = 0.0;
        for (int p = 0; p < 5; p++)
            acc += hp[p] * g0[p * 64 + e];
        g[e] = acc;
    }
    /* g[(c * 4 + l) * 8 + slot * 4 + m]: block (c, l) = sum g * matrix m of the slot */
    double *block = system + n * n;       /* r r scratch after the system */
    for (int c = 0; c < 2; c++) {
        for (int i = 0; i < r; i++)
            dz[c * r + i] = loads[c * r + i];
        for (int l = 0; l < 4; l++) {
            const double *gl = g + (c * 4 + l) * 8;
            const double w[6] = {gl[0], gl[1], gl[2], gl[4], gl[5], gl[6]};
            const double *m0 = slots, *m1 = slots + r2, *m2 = slots + 2 * r2;
            const double *m3 = slots + slot_size, *m4 = m3 + r2, *m5 = m3 + 2 * r2;
            for (int e = 0; e < r2; e++)
                block[e] = w[0] * m0[e] + w[1] * m1[e] + w[2] * m2[e] + w[3] * m3[e]
                           + w[4] * m4[e] + w[5] * m5[e];
            for (int i = 0; i < r; i++) {
                const double *row = block + i * r;
                if (l < 2) {
                    memcpy(system + (c * r + i) * n + l * r, row, sizeof(double) * r);
                } else {
                    const double *x = z2 + (l - 2) * r;
                    double acc = 0.0;
                    for (int k = 0; k < r; k++)
                        acc += row[k] * x[k];
                    dz[c * r + i] += acc;
                }
            }
        }
    }
    return solve(n, system, dz, dz);
}

/* The loads of one step (stage 1 and the sample in slots 1 and 0) and K^-1 f2_eig there. */
static int step_loads(const double *context, const double *pieces, const double *unit,
                      const double *scalars, int r, const double *slots, const double *points,
                      const double *angles, double *loads, double *static2)
{
    const int r2 = r * r, slot_size = 3 * r2 + r;
    double statics[MAX_SIZE], eigen[MAX_SIZE], trig[2 * MAX_LINKS];
    for (int point = 0; point < 2; point++) {       /* 0: stage 1 (slot 1), 1: sample (slot 0) */
        const double *slot = slots + (1 - point) * slot_size;
        if (solve(r, slot + 2 * r2, slot + 3 * r2, statics) < 0)
            return -1;
        link_trig(context, scalars, angles[point], trig);
        point_load(context, pieces, unit, trig, points + point * r, statics, loads + point * r,
                   eigen);
    }
    return solve(r, slots + 2 * r2, eigen, static2);
}

static PyObject *advance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 17) {
        PyErr_SetString(PyExc_TypeError, "advance(loads_context, pieces, unit, scalars, "
                        "step_context, mass, damping, kf, g0, out, rows, z_start, previous, "
                        "states, z2, static2, increments)");
        return NULL;
    }
    Py_buffer views[17];
    int held = 0;
    PyObject *result = NULL;
    double *work = NULL;
    for (; held < 17; held++)
        if (PyObject_GetBuffer(args[held], &views[held],
                               held >= 14 ? PyBUF_WRITABLE : PyBUF_SIMPLE) < 0)
            goto release;
    const double *context = views[0].buf, *sc = views[4].buf;
    if (views[0].len < C_HEADER * 8 || check_context(context, views[0].len / 8) < 0
        || views[4].len < STEP_HEADER * 8 || (int)sc[STEP_SIZE] != (int)context[C_SIZE]) {
        PyErr_SetString(PyExc_ValueError, "context: bad sizes");
        goto release;
    }
    StepTables st = {(int)sc[STEP_SIZE], (int)sc[STEP_GRID], (int)sc[STEP_MASS_GROUPS],
                     (int)sc[STEP_KF_GROUPS], (int)sc[STEP_OUT_ROWS], (int)sc[STEP_FIRST_MC],
                     (int)sc[STEP_GROUPS_C], sc[STEP_CELLS], views[5].buf, views[6].buf,
                     views[7].buf, views[9].buf};
    const int r = st.r, r2 = r * r;
    const Py_ssize_t n = views[10].len / (6 * 8);
    const Py_ssize_t need[17] = {
        0, 3 * (Py_ssize_t)context[C_ROWS] * r * 8, 36 * (Py_ssize_t)context[C_LINKS] * 8,
        (Py_ssize_t)context[C_GRID] * 4 * (Py_ssize_t)context[C_SCALARS] * 8, 0,
        (Py_ssize_t)st.grid * 2 * (st.first_mc + st.mass_groups > MONOMIAL_COUNT ? 0 : st.mass_groups) * r2 * 4,
        (Py_ssize_t)st.grid * 2 * st.groups_c * r2 * 4,
        (Py_ssize_t)st.grid * 2 * st.kf_groups * (r2 + r) * 8, 5 * 64 * 8,
        (Py_ssize_t)st.grid * st.out_rows * 4 * (r + 1) * 8, n * 6 * 8, 2 * r * 8, 3 * 8,
        n * 2 * r * 8, 2 * r * 8, r * 8, n * 4 * 8};
    if (st.grid < 1 || st.mass_groups < 1 || st.first_mc + st.mass_groups > MONOMIAL_COUNT
        || st.first_mc + st.groups_c > MONOMIAL_COUNT || st.kf_groups < 1
        || st.kf_groups > MONOMIAL_COUNT || st.out_rows < 1 || st.out_rows > 4 * MONOMIAL_COUNT) {
        PyErr_SetString(PyExc_ValueError, "step context: bad sizes");
        goto release;
    }
    for (int i = 0; i < 17; i++)
        if (views[i].len < need[i]) {
            PyErr_Format(PyExc_ValueError, "argument %d holds %zd bytes, needs %zd", i,
                         views[i].len, need[i]);
            goto release;
        }
    const int slot_size = 3 * r2 + r;
    work = PyMem_Malloc(sizeof(double) * (2 * slot_size + 5 * r2 + 8 * r));
    if (work == NULL) {
        PyErr_NoMemory();
        goto release;
    }
    double *slots = work, *system = slots + 2 * slot_size, *loads = system + 5 * r2;
    double *dz = loads + 2 * r, *points = dz + 2 * r, *x = points + 2 * r;
    const double *rows = views[10].buf, *z_start = views[11].buf, *states = views[13].buf;
    const double *previous = views[12].buf;
    double *z2 = views[14].buf, *static2 = views[15].buf, *increments = views[16].buf;
    const double c1 = sc[STEP_C1], g1 = sc[STEP_G1], g2 = sc[STEP_G2];
    double crank[3] = {previous[0], previous[1], previous[2]};
    for (Py_ssize_t m = 0; m < n; m++) {
        const double *row = rows + 6 * m, h = row[0];
        const double *before = m ? states + (m - 1) * 2 * r : z_start, *after = states + m * 2 * r;
        double stage_angle = fmod(crank[0] + c1 * row[5], TWO_PI);
        if (stage_angle < 0.0)
            stage_angle += TWO_PI;
        load_slot(&st, row[2], row[3], row[4], slots);
        load_slot(&st, stage_angle, crank[1] + c1 * (row[3] - crank[1]),
                  crank[2] + c1 * (row[4] - crank[2]), slots + slot_size);
        for (int i = 0; i < r; i++) {
            const double q = before[i], v = before[r + i];
            points[i] = q + (c1 - g1) * h * v + g1 * (after[i] - q) + g2 * h * (after[r + i] - v);
            points[r + i] = after[i];
        }
        const double angles[2] = {stage_angle, row[2]};
        if (step_loads(context, views[1].buf, views[2].buf, views[3].buf, r, slots, points,
                       angles, loads, static2) < 0
            || second_increment(r, views[8].buf, h, slots, z2, loads, system, dz) < 0) {
            PyErr_SetString(PyExc_ValueError, "singular second-order step");
            goto release;
        }
        for (int i = 0; i < 2 * r; i++)
            z2[i] += dz[i];
        for (int i = 0; i < r; i++)
            x[i] = z2[i] - static2[i];
        output_increment(&st, row[2], row[3], row[4], x, increments + 4 * m);
        crank[0] = row[2];
        crank[1] = row[3];
        crank[2] = row[4];
    }
    result = Py_None;
    Py_INCREF(result);
release:
    PyMem_Free(work);
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"loads", (PyCFunction)(void (*)(void))loads, METH_FASTCALL,
     "loads(context, pieces, unit, scalars, stored, states, out, angle_stage, angle_sample, "
     "stage_slot, sample_slot): the dynamic second-order pass's loads of one step (see the "
     "module's C source)."},
    {"advance", (PyCFunction)(void (*)(void))advance, METH_FASTCALL,
     "advance(loads_context, pieces, unit, scalars, step_context, mass, damping, kf, g0, out, "
     "rows, z_start, previous, states, z2, static2, increments): the second state through "
     "rows the compiled linear step took (see the module's C source)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_second_order_dynamic",
    "The dynamic second-order pass's loads per sample, compiled "
    "(core/estimation/second_order_dynamic_kernel.py).", -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__second_order_dynamic(void)
{
    return PyModule_Create(&module);
}
