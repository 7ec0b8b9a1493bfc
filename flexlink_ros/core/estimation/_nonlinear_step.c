/*
 * One Radau IIA step of the reduced nonlinear model by simplified Newton, compiled: the twin of
 * NonlinearStepper._newton in flexlink_ros/core/estimation/nonlinear_stream.py (its numpy
 * reference; a test compares the two). Plain C API, no numpy headers.
 *
 * newton(mass, damping, stiffness, load, chord, chord_rate, shortening, shortening_rate,
 *        axial_stiffness, speed, q, v, acc, axial, a, a2, c,
 *        stages, size, links, h, beta, nonlinear, tolerance, iterations) -> int
 *
 *   mass, damping, stiffness (s m m), load (s m): the linear part at the stages;
 *   chord, chord_rate (s E m), shortening, shortening_rate (s E m m): the lumped strain's
 *   tables at the stages; axial_stiffness (E); speed (s); q, v (m): the state;
 *   acc (s m): the starting stage accelerations, overwritten by the solution;
 *   axial (E): written, the last stage's N_L; a, a2 (s s), c (s): the method.
 *
 * Returns the Newton iterations taken, 0 if Newton did not converge (acc is then garbage).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "_doubles.h"

#define ARGS 25

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

static PyObject *newton(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != ARGS) {
        PyErr_SetString(PyExc_TypeError, "newton takes 25 arguments (see the module notes)");
        return NULL;
    }
    Problem p;
    p.s = PyLong_AsSsize_t(args[17]);
    p.m = PyLong_AsSsize_t(args[18]);
    p.e = PyLong_AsSsize_t(args[19]);
    p.h = PyFloat_AsDouble(args[20]);
    p.beta = PyFloat_AsDouble(args[21]);
    p.nonlinear = PyObject_IsTrue(args[22]);
    const double tolerance = PyFloat_AsDouble(args[23]);
    const Py_ssize_t iterations = PyLong_AsSsize_t(args[24]);
    if (PyErr_Occurred())
        return NULL;
    if (p.s < 1 || p.s > 8 || p.m < 1 || p.m > 4096 || p.e < 0 || p.e > 64) {
        PyErr_SetString(PyExc_ValueError, "newton: sizes out of range");
        return NULL;
    }
    const Py_ssize_t s = p.s, m = p.m, e = p.e;
    const Py_ssize_t counts[17] = {s * m * m, s * m * m, s * m * m, s * m, s * e * m, s * e * m,
                                   s * e * m * m, s * e * m * m, e, s, m, m, s * m, e, s * s,
                                   s * s, s};
    static const char *const names[17] = {
        "mass", "damping", "stiffness", "load", "chord", "chord_rate", "shortening",
        "shortening_rate", "axial_stiffness", "speed", "q", "v", "acc", "axial", "a", "a2", "c"};
    Py_buffer views[17];
    Py_ssize_t taken = 0;
    PyObject *result = NULL;
    for (; taken < 17; taken++)
        if (get_doubles(args[taken], &views[taken], counts[taken], names[taken],
                        taken == 12 || taken == 13) < 0)
            goto release;
    const double **in[] = {&p.mass, &p.damping, &p.stiffness, &p.load, &p.chord, &p.chord_rate,
                           &p.shortening, &p.shortening_rate, &p.k, &p.speed, &p.q, &p.v};
    for (Py_ssize_t i = 0; i < 12; i++)
        *in[i] = views[i].buf;
    p.acc = views[12].buf;
    p.axial = views[13].buf;
    p.a = views[14].buf;
    p.a2 = views[15].buf;
    p.c = views[16].buf;
    const Py_ssize_t n = s * m;
    double *mem = PyMem_Malloc((size_t)(3 * n + n * n + 2 * s * m * m + 4 * m) * sizeof(double));
    Py_ssize_t *piv = PyMem_Malloc((size_t)n * sizeof(Py_ssize_t));
    if (mem == NULL || piv == NULL) {
        PyErr_NoMemory();
    } else {
        Py_ssize_t count;
        Py_BEGIN_ALLOW_THREADS
        count = solve(&p, tolerance, iterations, mem, piv);
        Py_END_ALLOW_THREADS
        result = PyLong_FromSsize_t(count);
    }
    PyMem_Free(mem);
    PyMem_Free(piv);
release:
    for (Py_ssize_t i = 0; i < taken; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef METHODS[] = {
    {"newton", (PyCFunction)(void (*)(void))newton, METH_FASTCALL,
     "One Radau IIA step of the reduced nonlinear model by simplified Newton."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef MODULE = {PyModuleDef_HEAD_INIT, "_nonlinear_step",
                                    "The reduced nonlinear model's step (C).", -1, METHODS};

PyMODINIT_FUNC PyInit__nonlinear_step(void) { return PyModule_Create(&MODULE); }
