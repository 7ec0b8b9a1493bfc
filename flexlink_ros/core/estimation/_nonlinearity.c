/*
 * The validity indicator of one estimate, compiled: the per-sample form of
 * flexlink_ros/core/estimation/nonlinearity.py (NonlinearityIndicator.__call__, its Python twin
 * and reference; a test compares the two). Plain C API, no numpy headers. The kernel is
 * _nonlinearity.h, which the streaming update's compiled path (_radau_step.c) shares.
 *
 * indicator(context, table, state, angle, speed, accel) -> float
 * indicator_rows(context, table, states, angles, speeds, accels, out) -> None
 *
 *   context, table, state: float64 buffers as _nonlinearity.h describes; states: m rows of
 *   a state; angles, speeds, accels, out: m values (the offline replay's batch).
 *
 * Returns the detuning ratio of core/validity.py (Eq. 3), NaN for a non-finite speed or
 * acceleration.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "_doubles.h"
#include "_nonlinearity.h"

static PyObject *indicator(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError,
                        "indicator(context, table, state, angle, speed, accel)");
        return NULL;
    }
    const double angle = PyFloat_AsDouble(args[3]);
    const double speed = PyFloat_AsDouble(args[4]);
    const double accel = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred())
        return NULL;
    Py_buffer context_view, table_view, state_view;
    if (get_doubles(args[0], &context_view, INDICATOR_HEADER, "context", 0) < 0)
        return NULL;
    const double *context = context_view.buf;
    PyObject *result = NULL;
    const Py_ssize_t needed = indicator_context_size(
        context, context_view.len / (Py_ssize_t)sizeof(double));
    if (needed < 0) {
        PyErr_SetString(PyExc_ValueError, "context: bad sizes");
        goto release_context;
    }
    if (context_view.len < needed * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "context: too short for its reference modes");
        goto release_context;
    }
    if (get_doubles(args[1], &table_view, indicator_table_size(context), "table", 0) < 0)
        goto release_context;
    if (get_doubles(args[2], &state_view, 2 * (Py_ssize_t)context[INDICATOR_SIZE], "state", 0) < 0)
        goto release_table;
    result = PyFloat_FromDouble(indicator_value(context, table_view.buf, state_view.buf, angle,
                                                speed, accel));
    PyBuffer_Release(&state_view);
release_table:
    PyBuffer_Release(&table_view);
release_context:
    PyBuffer_Release(&context_view);
    return result;
}

/* The indicator of m samples into out (NonlinearityIndicator.batch). */
static PyObject *indicator_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError,
                        "indicator_rows(context, table, states, angles, speeds, accels, out)");
        return NULL;
    }
    Py_buffer views[7] = {{0}};
    PyObject *result = NULL;
    if (get_doubles(args[0], &views[0], INDICATOR_HEADER, "context", 0) < 0)
        return NULL;
    const double *context = views[0].buf;
    const Py_ssize_t needed = indicator_context_size(
        context, views[0].len / (Py_ssize_t)sizeof(double));
    if (needed < 0 || views[0].len < needed * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "context: bad sizes");
        goto release;
    }
    const Py_ssize_t width = 2 * (Py_ssize_t)context[INDICATOR_SIZE];
    if (get_doubles(args[6], &views[6], 0, "out", 1) < 0)
        goto release;
    const Py_ssize_t rows = views[6].len / (Py_ssize_t)sizeof(double);
    if (get_doubles(args[1], &views[1], indicator_table_size(context), "table", 0) < 0
        || get_doubles(args[2], &views[2], rows * width, "states", 0) < 0
        || get_doubles(args[3], &views[3], rows, "angles", 0) < 0
        || get_doubles(args[4], &views[4], rows, "speeds", 0) < 0
        || get_doubles(args[5], &views[5], rows, "accels", 0) < 0)
        goto release;
    const double *states = views[2].buf, *angles = views[3].buf, *speeds = views[4].buf,
                 *accels = views[5].buf;
    double *out = views[6].buf;
    for (Py_ssize_t m = 0; m < rows; m++)
        out[m] = indicator_value(context, views[1].buf, states + m * width, angles[m],
                                 speeds[m], accels[m]);
    result = Py_NewRef(Py_None);
release:
    for (int i = 0; i < 7; i++)
        if (views[i].obj != NULL)
            PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"indicator_rows", (PyCFunction)(void (*)(void))indicator_rows, METH_FASTCALL,
     "indicator_rows(context, table, states, angles, speeds, accels, out): the validity "
     "indicator of m estimates into out (see the module's C source)."},
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
