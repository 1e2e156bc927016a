/* numpy's rules for the C kernels, and numpy's arrays through the buffer interface.
 *
 * Included by the optional extensions whose loops must give numpy's numbers to the
 * bit (see setup.py): numpy's maximum and clip on ties and NaN, a contiguous float64
 * array (or one value for every row) and a contiguous intp index array, read from any
 * object with the buffer interface.
 */

#ifndef SANDBOX_NUMPY_RULES_H
#define SANDBOX_NUMPY_RULES_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* numpy.maximum(a, b): a where a > b or a is NaN, else b (b on a tie). */
static inline double
np_maximum(double a, double b)
{
    return (a > b || a != a) ? a : b;
}

/* numpy's clip with array bounds: max then min, the bound on a tie, NaN kept. */
static inline double
clip_rows(double x, double lo, double hi)
{
    double y = (x != x) ? x : (x > lo ? x : lo);
    return (y != y) ? y : (y < hi ? y : hi);
}

/* numpy's clip with scalar bounds: x itself on a tie, NaN kept. */
static inline double
clip_scalars(double x, double lo, double hi)
{
    if (x != x) {
        return x;
    }
    double y = (x < lo) ? lo : x;
    return (y > hi) ? hi : y;
}

/* A float64 buffer and its length. */
typedef struct {
    Py_buffer view;
    double *data;
    Py_ssize_t len;
    Py_ssize_t step; /* 0 for one value for every row */
} Rows;

static inline int
get_rows(PyObject *obj, Rows *rows, int writable)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, &rows->view, flags) < 0) {
        return -1;
    }
    if (rows->view.itemsize != 8 || rows->view.format == NULL ||
        strcmp(rows->view.format, "d") != 0) {
        PyBuffer_Release(&rows->view);
        PyErr_SetString(PyExc_TypeError, "expected a contiguous float64 array");
        return -1;
    }
    rows->data = (double *)rows->view.buf;
    rows->len = rows->view.len / 8;
    rows->step = rows->len == 1 ? 0 : 1;
    return 0;
}

static inline void
release(Rows *rows, int count)
{
    for (int k = 0; k < count; k++) {
        PyBuffer_Release(&rows[k].view);
    }
}

/* An index array (numpy's intp) and its length. */
typedef struct {
    Py_buffer view;
    const Py_ssize_t *data;
    Py_ssize_t len;
} Indices;

static inline int
get_indices(PyObject *obj, Indices *out)
{
    if (PyObject_GetBuffer(obj, &out->view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        return -1;
    }
    const char *f = out->view.format;
    if (out->view.itemsize != (Py_ssize_t)sizeof(Py_ssize_t) || f == NULL ||
        (strcmp(f, "l") != 0 && strcmp(f, "q") != 0 && strcmp(f, "n") != 0)) {
        PyBuffer_Release(&out->view);
        PyErr_SetString(PyExc_TypeError, "expected a contiguous intp array");
        return -1;
    }
    out->data = (const Py_ssize_t *)out->view.buf;
    out->len = out->view.len / (Py_ssize_t)sizeof(Py_ssize_t);
    return 0;
}

#endif
