/*
 * The validity indicator of one estimate, compiled: the per-sample form of
 * flexlink_ros/core/estimation/nonlinearity.py (NonlinearityIndicator.__call__, its Python twin
 * and reference; a test compares the two). Plain C API, no numpy headers. The kernel is
 * _nonlinearity.h, which the streaming update's compiled path (_radau_step.c) shares.
 *
 * indicator(context, table, state, angle, speed, accel) -> float
 *
 *   context, table, state: float64 buffers as _nonlinearity.h describes.
 *
 * Returns the detuning ratio of core/validity.py (Eq. 3), NaN for a non-finite speed or
 * acceleration.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "_nonlinearity.h"

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
    const double speed = PyFloat_AsDouble(args[4]);
    const double accel = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred())
        return NULL;
    Py_buffer context_view, table_view, state_view;
    if (get_doubles(args[0], &context_view, INDICATOR_HEADER, "context") < 0)
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
    if (get_doubles(args[1], &table_view, indicator_table_size(context), "table") < 0)
        goto release_context;
    if (get_doubles(args[2], &state_view, 2 * (Py_ssize_t)context[INDICATOR_SIZE], "state") < 0)
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
