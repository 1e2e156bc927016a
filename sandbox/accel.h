/* What the compiled paths share: numpy's arrays read and made, a few plain helpers.
 *
 * Included by every extension of sandbox/accel.py's registry but _cstep: a
 * contiguous float64 array (or one value for every row), a contiguous intp index
 * array and a contiguous array of one-byte elements, read from any object with the
 * buffer interface (an ndarray through numpy's C API where the build has its
 * headers), and new arrays made through numpy's C API; the larger and the smaller
 * of two numbers, a clamp, and an angle wrapped around the circle.
 */

#ifndef SANDBOX_ACCEL_H
#define SANDBOX_ACCEL_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* With numpy's headers (setup.py defines SANDBOX_NUMPY_API where numpy is there at
 * build time) an ndarray's data is read through numpy's C API: a few field reads,
 * where the buffer interface makes and frees a description of the array at every
 * call (most of a small loop's cost, on the new arrays of every period). Any other
 * object, or a build without the headers, takes the buffer interface as before. The
 * API is imported at the first array read (_import_array), once per extension. */
#ifdef SANDBOX_NUMPY_API
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

/* The ndarray ``obj``'s data if it is a C-contiguous, aligned array of ``type``
 * (and writable if asked), else NULL with no error set (the buffer path decides). */
static inline void *
numpy_data(PyObject *obj, int type, int writable, Py_ssize_t *count)
{
    if (PyArray_API == NULL) {
        if (_import_array() < 0) {
            PyErr_Clear();
            return NULL;
        }
    }
    if (!PyArray_CheckExact(obj)) {
        return NULL;
    }
    PyArrayObject *a = (PyArrayObject *)obj;
    int need = NPY_ARRAY_C_CONTIGUOUS | NPY_ARRAY_ALIGNED |
               (writable ? NPY_ARRAY_WRITEABLE : 0);
    if ((PyArray_FLAGS(a) & need) != need || PyArray_TYPE(a) != type) {
        return NULL;
    }
    *count = PyArray_SIZE(a);
    return PyArray_DATA(a);
}
#endif

/* 1 where this build makes new arrays through numpy's C API (new_array). */
#ifdef SANDBOX_NUMPY_API
#define SANDBOX_ALLOCATES 1
#else
#define SANDBOX_ALLOCATES 0
#endif

/* A new C-contiguous ndarray of ``nd`` (1 or 2) dimensions ``d0``, ``d1``,
 * float64 (or bool where ``boolean``), uninitialised: through numpy's C API, the
 * cost of a few field writes where numpy.empty's call costs a fifth of a
 * microsecond. NULL with TypeError set where the build lacks numpy's headers (the
 * caller then passes arrays it made). */
static inline PyObject *
new_array(int nd, Py_ssize_t d0, Py_ssize_t d1, int boolean)
{
#ifdef SANDBOX_NUMPY_API
    if (PyArray_API == NULL && _import_array() < 0) {
        return NULL;
    }
    npy_intp dims[2] = {d0, d1};
    return PyArray_EMPTY(nd, dims, boolean ? NPY_BOOL : NPY_DOUBLE, 0);
#else
    (void)nd;
    (void)d0;
    (void)d1;
    (void)boolean;
    PyErr_SetString(PyExc_TypeError, "built without numpy's headers: pass arrays");
    return NULL;
#endif
}

/* The larger of a and b (b where they are equal or one is NaN). */
static inline double
larger(double a, double b)
{
    return a > b ? a : b;
}

/* The smaller of a and b (b where they are equal or one is NaN). */
static inline double
smaller(double a, double b)
{
    return a < b ? a : b;
}

/* x raised to lo, then lowered to hi (x itself where it is NaN). */
static inline double
clamp(double x, double lo, double hi)
{
    double y = x < lo ? lo : x;
    return y > hi ? hi : y;
}

/* The angle a [rad] moved by whole turns into [-pi, pi]: (a + pi) mod 2 pi - pi. */
static inline double
wrapped(double a)
{
    double w = fmod(a + M_PI, 2.0 * M_PI);
    return (w < 0.0 ? w + 2.0 * M_PI : w) - M_PI;
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
#ifdef SANDBOX_NUMPY_API
    Py_ssize_t count;
    double *data = (double *)numpy_data(obj, NPY_DOUBLE, writable, &count);
    if (data != NULL) {
        memset(&rows->view, 0, sizeof(Py_buffer)); /* nothing to release */
        rows->data = data;
        rows->len = count;
        rows->step = count == 1 ? 0 : 1;
        return 0;
    }
#endif
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

/* ``count`` float64 arrays ``objs`` into ``rows`` (get_rows), those from
 * ``first_writable`` on writable; on an error the ones read are released. */
static inline int
get_all_rows(PyObject *const *objs, Rows *rows, int count, int first_writable)
{
    for (int k = 0; k < count; k++) {
        if (get_rows(objs[k], &rows[k], k >= first_writable) < 0) {
            release(rows, k);
            return -1;
        }
    }
    return 0;
}

/* The module of ``def`` with its constant ALLOCATES: whether its calls make their
 * output arrays themselves (new_array), where a caller may pass None for them. */
static inline PyObject *
module_allocating(PyModuleDef *def)
{
    PyObject *m = PyModule_Create(def);
    if (m != NULL && PyModule_AddIntConstant(m, "ALLOCATES", SANDBOX_ALLOCATES) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}

/* A contiguous array of one-byte elements (numpy's bool or int8) in ``view``:
 * through numpy's C API where it can (``view->obj`` NULL: nothing to release), else
 * the buffer interface (C-contiguous, and writable if asked). */
static inline int
get_bytes(PyObject *obj, Py_buffer *view, int writable)
{
#ifdef SANDBOX_NUMPY_API
    Py_ssize_t count;
    void *data = numpy_data(obj, NPY_BOOL, writable, &count);
    if (data == NULL) {
        data = numpy_data(obj, NPY_INT8, writable, &count);
    }
    if (data != NULL) {
        memset(view, 0, sizeof(Py_buffer));
        view->buf = data;
        view->len = count;
        view->itemsize = 1;
        view->readonly = !writable;
        return 0;
    }
#endif
    return PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS |
                                             (writable ? PyBUF_WRITABLE : 0));
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
#ifdef SANDBOX_NUMPY_API
    Py_ssize_t count;
    const Py_ssize_t *data =
        (const Py_ssize_t *)numpy_data(obj, NPY_INTP, 0, &count);
    if (data != NULL) {
        memset(&out->view, 0, sizeof(Py_buffer)); /* nothing to release */
        out->data = data;
        out->len = count;
        return 0;
    }
#endif
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
