/*
 * The per-sample loads of the dynamic second-order pass, compiled: the form of
 * flexlink_ros/core/estimation/dynamic_pass_kernel.py (DynamicPassKernel, whose numpy path is
 * its twin and reference; a test compares the two). Plain C API, no numpy headers.
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
 * (core/reduction/dynamic_second_order_tables.py, element_loads).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#define TWO_PI 6.283185307179586
#define MAX_SIZE 64
#define MAX_LINKS 8
#define MAX_ROWS 512
enum { C_SIZE, C_ROWS, C_LINKS, C_GRID, C_SCALARS, C_HEADER };

/* Solve a x = b (n x n, row-major, copied) by Gaussian elimination with partial pivoting. */
static int solve(int n, const double *matrix, const double *b, double *x)
{
    double a[MAX_SIZE * MAX_SIZE];
    memcpy(a, matrix, sizeof(double) * n * n);
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

static int get_doubles(PyObject *object, Py_buffer *view, Py_ssize_t count, const char *what,
                       int writable)
{
    if (PyObject_GetBuffer(object, view, writable ? PyBUF_WRITABLE : PyBUF_SIMPLE) < 0)
        return -1;
    if (view->len < count * (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "%s holds %zd bytes, needs %zd", what, view->len,
                     count * (Py_ssize_t)sizeof(double));
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
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

static PyMethodDef methods[] = {
    {"loads", (PyCFunction)(void (*)(void))loads, METH_FASTCALL,
     "loads(context, pieces, unit, scalars, stored, states, out, angle_stage, angle_sample, "
     "stage_slot, sample_slot): the dynamic second-order pass's loads of one step (see the "
     "module's C source)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_dynamic_second_order",
    "The dynamic second-order pass's loads per sample, compiled "
    "(core/estimation/dynamic_pass_kernel.py).", -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__dynamic_second_order(void)
{
    return PyModule_Create(&module);
}
