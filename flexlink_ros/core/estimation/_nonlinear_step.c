/*
 * One Radau IIA step of the reduced nonlinear model by simplified Newton, compiled: the twin of
 * NonlinearStepper._newton in flexlink_ros/core/estimation/nonlinear_stream.py (its numpy
 * reference; a test compares the two). Plain C API, no numpy headers.
 *
 * step(...): see its notes below. The linear part is formed from the interpolated table rows,
 * then the stage accelerations are solved by simplified Newton (the Jacobian formed at the
 * step's start and again when an iteration contracts by less than half).
 *
 * Returns the Newton iterations taken, 0 if Newton did not converge (acc is then not a solution
 * and the caller keeps its state).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "_doubles.h"


typedef struct {
    const double *mass, *damping, *stiffness, *load, *chord, *chord_rate, *shortening,
        *shortening_rate, *k, *speed, *q, *v, *a, *a2, *c;
    double *acc, *axial;
    Py_ssize_t s, m, e;
    double h, beta;
    int nonlinear;
} Problem;

/* Lumped force change (force: s m) and, if fq, its tangents (fq, fv: s m m, added to). */
static void lumped(const Problem *p, const double *disp, const double *vel, double *force,
                   double *fq, double *fv, double *axial_last, double *work)
{
    const Py_ssize_t m = p->m, e = p->e;
    double *gq = work, *grad = work + m, *dax = work + 2 * m, *sq = work + 3 * m;
    memset(force, 0, (size_t)(p->s * m) * sizeof(double));
    for (Py_ssize_t i = 0; i < p->s; i++) {
        const double w = p->speed[i], *x = disp + i * m, *xd = vel + i * m;
        for (Py_ssize_t l = 0; l < e; l++) {
            const double *ch = p->chord + (i * e + l) * m, *cr = p->chord_rate + (i * e + l) * m;
            const double *g = p->shortening + (i * e + l) * m * m;
            const double *hr = p->shortening_rate + (i * e + l) * m * m;
            const double k = p->k[l];
            double ce = 0.0, cv = 0.0, crx = 0.0;
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
            for (Py_ssize_t a = 0; a < m; a++) {
                double sg = 0.0, sh = 0.0, sv = 0.0;
                for (Py_ssize_t b = 0; b < m; b++) {
                    sg += g[a * m + b] * x[b];
                    sh += hr[a * m + b] * x[b];
                    sv += g[a * m + b] * xd[b];
                }
                gq[a] = sg;
                sq[a] = sh;
                grad[a] = ch[a] + sg;
                dax[a] = sv;
                half += sg * x[a];
                quad += x[a] * sh;
            }
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
            /* (h + h^T) x: sq holds h x; add h^T x */
            for (Py_ssize_t a = 0; a < m; a++) {
                double t = 0.0;
                for (Py_ssize_t b = 0; b < m; b++)
                    t += hr[b * m + a] * x[b];
                dax[a] = k * (grad[a] + p->beta * (dax[a] + w * (cr[a] + sq[a] + t)));
            }
            double *kq = fq + i * m * m, *kv = fv + i * m * m;
            const double bw = p->beta * w, bk = p->beta * k;
            for (Py_ssize_t a = 0; a < m; a++) {
                for (Py_ssize_t b = 0; b < m; b++) {
                    kq[a * m + b] += grad[a] * dax[b] + n * g[a * m + b]
                                     - k * ch[a] * (ch[b] + bw * cr[b]);
                    kv[a * m + b] += bk * (grad[a] * grad[b] - ch[a] * ch[b]);
                }
            }
        }
    }
    (void)gq;
}

/* LU with partial pivoting in place (n x n, row-major); 0 if singular. */
static int lu_factor(double *a, Py_ssize_t n, Py_ssize_t *piv)
{
    for (Py_ssize_t col = 0; col < n; col++) {
        Py_ssize_t best = col;
        for (Py_ssize_t r = col + 1; r < n; r++)
            if (fabs(a[r * n + col]) > fabs(a[best * n + col]))
                best = r;
        piv[col] = best;
        if (a[best * n + col] == 0.0)
            return 0;
        if (best != col)
            for (Py_ssize_t j = 0; j < n; j++) {
                double t = a[col * n + j];
                a[col * n + j] = a[best * n + j];
                a[best * n + j] = t;
            }
        const double inv = 1.0 / a[col * n + col];
        for (Py_ssize_t r = col + 1; r < n; r++) {
            const double f = (a[r * n + col] *= inv);
            if (f != 0.0)
                for (Py_ssize_t j = col + 1; j < n; j++)
                    a[r * n + j] -= f * a[col * n + j];
        }
    }
    return 1;
}

static void lu_solve(const double *a, Py_ssize_t n, const Py_ssize_t *piv, double *b)
{
    for (Py_ssize_t i = 0; i < n; i++) {
        double t = b[piv[i]];
        b[piv[i]] = b[i];
        b[i] = t;
        for (Py_ssize_t j = 0; j < i; j++)
            b[i] -= a[i * n + j] * b[j];
    }
    for (Py_ssize_t i = n - 1; i >= 0; i--) {
        for (Py_ssize_t j = i + 1; j < n; j++)
            b[i] -= a[i * n + j] * b[j];
        b[i] /= a[i * n + i];
    }
}

/* Stage states, the residual (res: s m) and, if jac, the step matrix (s m x s m). */
static void residual(const Problem *p, double *disp, double *vel, double *res, double *jac,
                     double *fq, double *fv, double *work)
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
            double r = res[i * m + a] - p->load[i * m + a];
            for (Py_ssize_t b = 0; b < m; b++)
                r += mm[a * m + b] * p->acc[i * m + b] + cc[a * m + b] * vel[i * m + b]
                     + kk[a * m + b] * disp[i * m + b];
            res[i * m + a] = r;
        }
        if (jac == NULL)
            continue;
        for (Py_ssize_t j = 0; j < s; j++) {
            const double ha = p->h * p->a[i * s + j], hh = p->h * p->h * p->a2[i * s + j];
            for (Py_ssize_t a = 0; a < m; a++)
                for (Py_ssize_t b = 0; b < m; b++) {
                    const Py_ssize_t ab = a * m + b, im = i * m * m;
                    jac[(i * m + a) * n + j * m + b] =
                        (i == j ? mm[ab] : 0.0) + ha * (cc[ab] + fv[im + ab])
                        + hh * (kk[ab] + fq[im + ab]);
                }
        }
    }
}

static Py_ssize_t solve(Problem *p, double tolerance, Py_ssize_t iterations, double *mem,
                        Py_ssize_t *piv)
{
    const Py_ssize_t s = p->s, m = p->m, n = s * m;
    double *disp = mem, *vel = disp + n, *res = vel + n, *jac = res + n, *fq = jac + n * n;
    double *fv = fq + s * m * m, *work = fv + s * m * m;
    int fresh = 0;
    double previous = INFINITY;
    for (Py_ssize_t count = 1; count <= iterations; count++) {
        residual(p, disp, vel, res, fresh ? NULL : jac, fq, fv, work);
        if (!fresh) {
            if (!lu_factor(jac, n, piv))
                return 0;
            fresh = 1;
        }
        for (Py_ssize_t i = 0; i < n; i++)
            res[i] = -res[i];
        lu_solve(jac, n, piv, res);
        double size = 0.0, scale = 0.0;
        for (Py_ssize_t i = 0; i < n; i++) {
            p->acc[i] += res[i];
            size = fmax(size, fabs(res[i]));
            scale = fmax(scale, fabs(p->acc[i]));
        }
        if (!isfinite(size))
            return 0;
        if (size <= tolerance * scale || size == 0.0)
            return count;
        if (size > 0.5 * previous)
            fresh = 0;
        previous = size;
    }
    return 0;
}

/*
 * step(row, offsets, bearing, speed, accel, q, v, acc, axial, axial_stiffness, a, a2, c,
 *      stages, size, links, fields, h, beta, nonlinear, tolerance, iterations) -> int
 *
 * As newton, with the linear part formed here from the interpolated table rows (s x fields,
 * NonlinearTables.at's flat row) at the offsets (float64) of mass, gyroscopic, coupling_a,
 * coupling_w2, elastic, elastic_rate, geometric_1, geometric_a, geometric_w2, load_1,
 * load_a, load_w2, chord, chord_rate, shortening, shortening_rate (the layout's order):
 * C = w G + beta (K_el + K_bear), K = K_el + K_bear + beta w K1 + a K_a + w^2 K_w2 (+ K_G
 * for the linear model), R = f_1 + a f_a + w^2 f_w2, as linear_part in nonlinear_stream.py.
 */
#define STEP_ARGS 22
#define OFFSETS 16

static void gather_linear(const double *row, const double *off, const double *bearing,
                          const Problem *p, double accel, Py_ssize_t fields, double *mass,
                          double *damping, double *stiffness, double *load, double *tables)
{
    const Py_ssize_t m = p->m, mm = m * m, e = p->e, s = p->s;
    for (Py_ssize_t i = 0; i < s; i++) {
        const double *r = row + i * fields, w = p->speed[i];
#define AT(k) (r + (Py_ssize_t)off[k])
        const double *gy = AT(1), *ca = AT(2), *cw = AT(3), *el = AT(4), *er = AT(5),
                     *g1 = AT(6), *ga = AT(7), *gw = AT(8);
        memcpy(mass + i * mm, AT(0), (size_t)mm * sizeof(double));
        for (Py_ssize_t j = 0; j < mm; j++) {
            const double elastic = el[j] + bearing[j];
            damping[i * mm + j] = w * gy[j] + p->beta * elastic;
            double k = elastic + p->beta * w * er[j] + accel * ca[j] + w * w * cw[j];
            if (!p->nonlinear)
                k += g1[j] + accel * ga[j] + w * w * gw[j];
            stiffness[i * mm + j] = k;
        }
        for (Py_ssize_t j = 0; j < m; j++)
            load[i * m + j] = AT(9)[j] + accel * AT(10)[j] + w * w * AT(11)[j];
        /* chord, chord_rate (s E m) and shortening, shortening_rate (s E m m), contiguous */
        memcpy(tables + i * e * m, AT(12), (size_t)(e * m) * sizeof(double));
        memcpy(tables + s * e * m + i * e * m, AT(13), (size_t)(e * m) * sizeof(double));
        memcpy(tables + 2 * s * e * m + i * e * mm, AT(14), (size_t)(e * mm) * sizeof(double));
        memcpy(tables + 2 * s * e * m + s * e * mm + i * e * mm, AT(15),
               (size_t)(e * mm) * sizeof(double));
#undef AT
    }
}

static PyObject *step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != STEP_ARGS) {
        PyErr_SetString(PyExc_TypeError, "step takes 22 arguments (see the module notes)");
        return NULL;
    }
    Problem p;
    p.s = PyLong_AsSsize_t(args[13]);
    p.m = PyLong_AsSsize_t(args[14]);
    p.e = PyLong_AsSsize_t(args[15]);
    const Py_ssize_t fields = PyLong_AsSsize_t(args[16]);
    p.h = PyFloat_AsDouble(args[17]);
    p.beta = PyFloat_AsDouble(args[18]);
    p.nonlinear = PyObject_IsTrue(args[19]);
    const double tolerance = PyFloat_AsDouble(args[20]);
    const Py_ssize_t iterations = PyLong_AsSsize_t(args[21]);
    const double accel = PyFloat_AsDouble(args[4]);
    if (PyErr_Occurred())
        return NULL;
    if (p.s < 1 || p.s > 8 || p.m < 1 || p.m > 4096 || p.e < 0 || p.e > 64 || fields < 1) {
        PyErr_SetString(PyExc_ValueError, "step: sizes out of range");
        return NULL;
    }
    const Py_ssize_t s = p.s, m = p.m, e = p.e, n = s * m;
    const Py_ssize_t counts[13] = {s * fields, OFFSETS, m * m, s, 1, m, m, s * m, e, e, s * s,
                                   s * s, s};
    static const char *const names[13] = {"row", "offsets", "bearing", "speed", "accel", "q",
                                          "v", "acc", "axial", "axial_stiffness", "a", "a2",
                                          "c"};
    Py_buffer views[13];
    Py_ssize_t taken = 0;
    PyObject *result = NULL;
    for (; taken < 13; taken++) {
        if (taken == 4)
            continue;       /* accel is a float */
        if (get_doubles(args[taken], &views[taken], counts[taken], names[taken],
                        taken == 7 || taken == 8) < 0)
            goto release;
    }
    const double *off = views[1].buf;
    for (Py_ssize_t k = 0; k < OFFSETS; k++)
        if (off[k] < 0.0 || off[k] >= (double)fields) {
            PyErr_SetString(PyExc_ValueError, "step: an offset is outside the row");
            goto release;
        }
    if (off[15] + (double)(e * m * m) > (double)fields) {
        PyErr_SetString(PyExc_ValueError, "step: the row is shorter than its layout");
        goto release;
    }
    p.speed = views[3].buf;
    p.q = views[5].buf;
    p.v = views[6].buf;
    p.acc = views[7].buf;
    p.axial = views[8].buf;
    p.k = views[9].buf;
    p.a = views[10].buf;
    p.a2 = views[11].buf;
    p.c = views[12].buf;
    const size_t linear = (size_t)(3 * s * m * m + s * m + 2 * s * e * m + 2 * s * e * m * m);
    double *lin = PyMem_Malloc(linear * sizeof(double));
    double *mem = PyMem_Malloc((size_t)(3 * n + n * n + 2 * s * m * m + 4 * m) * sizeof(double));
    Py_ssize_t *piv = PyMem_Malloc((size_t)n * sizeof(Py_ssize_t));
    if (lin == NULL || mem == NULL || piv == NULL) {
        PyErr_NoMemory();
    } else {
        double *mass = lin, *damping = mass + s * m * m, *stiffness = damping + s * m * m;
        double *load = stiffness + s * m * m, *tables = load + s * m;
        Py_ssize_t count;
        Py_BEGIN_ALLOW_THREADS
        gather_linear(views[0].buf, off, views[2].buf, &p, accel, fields, mass, damping,
                      stiffness, load, tables);
        p.mass = mass;
        p.damping = damping;
        p.stiffness = stiffness;
        p.load = load;
        p.chord = tables;
        p.chord_rate = tables + s * e * m;
        p.shortening = tables + 2 * s * e * m;
        p.shortening_rate = tables + 2 * s * e * m + s * e * m * m;
        count = solve(&p, tolerance, iterations, mem, piv);
        Py_END_ALLOW_THREADS
        result = PyLong_FromSsize_t(count);
    }
    PyMem_Free(lin);
    PyMem_Free(mem);
    PyMem_Free(piv);
release:
    for (Py_ssize_t i = 0; i < taken; i++)
        if (i != 4)
            PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef METHODS[] = {
    {"step", (PyCFunction)(void (*)(void))step, METH_FASTCALL,
     "One Radau IIA step of the reduced nonlinear model from its interpolated table rows."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef MODULE = {PyModuleDef_HEAD_INIT, "_nonlinear_step",
                                    "The reduced nonlinear model's step (C).", -1, METHODS};

PyMODINIT_FUNC PyInit__nonlinear_step(void) { return PyModule_Create(&MODULE); }
