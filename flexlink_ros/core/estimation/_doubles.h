/*
 * get_doubles: a float64 buffer of at least `count` values (writable if asked), or -1 with
 * an exception set. The one buffer check of the small extensions (_nonlinearity.c,
 * _second_order_dynamic.c); include after Python.h.
 */
#ifndef FLEXLINK_DOUBLES_H
#define FLEXLINK_DOUBLES_H

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

#endif
