/*
 * The validity indicator of one estimate, compiled: the per-sample form of
 * flexlink_ros/core/estimation/nonlinearity.py (NonlinearityIndicator.__call__, its Python twin
 * and reference; a test compares the two). Plain C API, no numpy headers.
 *
 * indicator(context, table, state, angle, speed, accel) -> float
 *
 *   context  float64 buffer: grid, r, links, modes, speeds, zeta, speed_max, cells per radian,
 *            1 / (w^2 step of the reference grid), rest speed, then omega (speeds x modes) and
 *            shares (speeds x modes x links) of the reference modes (CONTEXT_* below).
 *   table    float64 buffer (grid, 4, links, 7 r + 3): the cells' spline coefficients of the
 *            rows of Eq. (1) of core/reduction/nonlinearity_tables.py over P_cr.
 *   state    float64 buffer (2 r): q, then q'.
 *
 * Returns the detuning ratio of core/validity.py (Eq. 3), NaN for a non-finite speed or
 * acceleration.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

enum {
    CONTEXT_GRID, CONTEXT_SIZE, CONTEXT_LINKS, CONTEXT_MODES, CONTEXT_SPEEDS, CONTEXT_ZETA,
    CONTEXT_SPEED_MAX, CONTEXT_CELL_SCALE, CONTEXT_INVERSE_STEP2, CONTEXT_REST_SPEED,
    CONTEXT_HEADER
};
#define MAX_LINKS 8
#define TWO_PI 6.283185307179586

static double dot(const double *a, const double *b, Py_ssize_t n)
{
    double sum = 0.0;
    for (Py_ssize_t i = 0; i < n; i++)
        sum += a[i] * b[i];
    return sum;
}

/* N_e / P_cr of each link at cell k, position t (Eq. 1 of nonlinearity_tables.py). */
static void link_ratios(const double *cell, const double *state, Py_ssize_t r, int links,
                        double t, double speed, double accel, double *ratios)
{
    const Py_ssize_t width = 7 * r + 3;
    const double w2 = speed * speed;
    const double mq[3] = {1.0, accel, w2};
    const double mv[4] = {1.0, speed, w2, w2 * w2};
    const double powers[4] = {1.0, t, t * t, t * t * t};
    for (int l = 0; l < links; l++)
        ratios[l] = 0.0;
    for (int p = 0; p < 4; p++) {
        for (int l = 0; l < links; l++) {
            const double *row = cell + (p * links + l) * width;
            double sum = row[7 * r] + accel * row[7 * r + 1] + w2 * row[7 * r + 2];
            for (int m = 0; m < 3; m++)
                sum += mq[m] * dot(row + m * r, state, r);
            for (int m = 0; m < 4; m++)
                sum += mv[m] * dot(row + (3 + m) * r, state + r, r);
            ratios[l] += powers[p] * sum;
        }
    }
}

/* max over the reference modes of |Delta omega| / sqrt(d^2 + (zeta omega)^2) (Eq. 3). */
static double detuning(const double *context, const double *ratios, double speed)
{
    const int modes = (int)context[CONTEXT_MODES], links = (int)context[CONTEXT_LINKS];
    const int speeds = (int)context[CONTEXT_SPEEDS];
    const double zeta = context[CONTEXT_ZETA], rate = fabs(speed);
    const double *omega = context + CONTEXT_HEADER;
    const double *share = omega + speeds * modes;
    const double position = speed * speed * context[CONTEXT_INVERSE_STEP2];
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
        if (rate > context[CONTEXT_REST_SPEED])     /* nearest k >= 1, ties to even */
            harmonic = fmax(nearbyint(om / rate), 1.0) * rate;
        const double value = fabs(0.5 * om * total) / hypot(om - harmonic, zeta * om);
        if (value > worst)
            worst = value;
    }
    return worst;
}

static int get_doubles(PyObject *object, Py_buffer *view, Py_ssize_t count, const char *what)
{
    if (PyObject_GetBuffer(object, view, PyBUF_SIMPLE) < 0)
        return -1;
    if (view->len < count * (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "%s holds %zd bytes, needs %zd", what, view->len,
                     count * (Py_ssize_t)sizeof(double));
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static PyObject *indicator(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError,
                        "indicator(context, table, state, angle, speed, accel)");
        return NULL;
    }
    const double angle = PyFloat_AsDouble(args[3]);
    double speed = PyFloat_AsDouble(args[4]);
    const double accel = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred())
        return NULL;
    Py_buffer context_view, table_view, state_view;
    if (get_doubles(args[0], &context_view, CONTEXT_HEADER, "context") < 0)
        return NULL;
    const double *context = context_view.buf;
    const Py_ssize_t grid = (Py_ssize_t)context[CONTEXT_GRID], r = (Py_ssize_t)context[CONTEXT_SIZE];
    const int links = (int)context[CONTEXT_LINKS], modes = (int)context[CONTEXT_MODES];
    const int speeds = (int)context[CONTEXT_SPEEDS];
    PyObject *result = NULL;
    if (links < 1 || links > MAX_LINKS || modes < 1 || speeds < 2 || grid < 1 || r < 1) {
        PyErr_SetString(PyExc_ValueError, "context: bad sizes");
        goto release_context;
    }
    if (context_view.len < (CONTEXT_HEADER + (Py_ssize_t)speeds * modes * (1 + links))
                           * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "context: too short for its reference modes");
        goto release_context;
    }
    if (get_doubles(args[1], &table_view, grid * 4 * links * (7 * r + 3), "table") < 0)
        goto release_context;
    if (get_doubles(args[2], &state_view, 2 * r, "state") < 0)
        goto release_table;
    if (!(isfinite(speed) && isfinite(accel) && isfinite(angle))) {
        result = PyFloat_FromDouble(NAN);
        goto release_state;
    }
    double x = fmod(angle, TWO_PI);
    if (x < 0.0)
        x += TWO_PI;
    x *= context[CONTEXT_CELL_SCALE];
    Py_ssize_t k = (Py_ssize_t)x;
    if (k > grid - 1)
        k = grid - 1;
    const double speed_max = context[CONTEXT_SPEED_MAX];
    speed = speed > speed_max ? speed_max : (speed < -speed_max ? -speed_max : speed);
    double ratios[MAX_LINKS];
    link_ratios((const double *)table_view.buf + k * 4 * links * (7 * r + 3),
                state_view.buf, r, links, x - k, speed, accel, ratios);
    result = PyFloat_FromDouble(detuning(context, ratios, speed));
release_state:
    PyBuffer_Release(&state_view);
release_table:
    PyBuffer_Release(&table_view);
release_context:
    PyBuffer_Release(&context_view);
    return result;
}

static PyMethodDef methods[] = {
    {"indicator", (PyCFunction)(void (*)(void))indicator, METH_FASTCALL,
     "indicator(context, table, state, angle, speed, accel) -> float: the validity indicator "
     "of one estimate (see the module's C source)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_nonlinearity",
    "The validity indicator of one estimate, compiled (core/estimation/nonlinearity.py).", -1,
    methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__nonlinearity(void)
{
    return PyModule_Create(&module);
}
