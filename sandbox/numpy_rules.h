/* numpy's rules for the C kernels, and numpy's arrays through the buffer interface.
 *
 * Included by the optional extensions whose loops must give numpy's numbers to the
 * bit (see setup.py): numpy's maximum, clip and remainder on ties, NaN and signs; a
 * contiguous float64 array (or one value for every row), a contiguous intp index
 * array and a contiguous bool array, read from any object with the buffer interface
 * (an ndarray through numpy's C API where the build has its headers).
 */

#ifndef SANDBOX_NUMPY_RULES_H
#define SANDBOX_NUMPY_RULES_H

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

/* numpy.remainder(a, b) of floats: fmod, moved to b's sign, +-0 with b's sign. */
static inline double
np_remainder(double a, double b)
{
    double mod = fmod(a, b);
    if (!b) {
        return mod;
    }
    if (mod) {
        if ((b < 0) != (mod < 0)) {
            mod += b;
        }
    }
    else {
        mod = copysign(0.0, b);
    }
    return mod;
}

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

/* A module's ``elementwise(op, a, b, out)`` for its checks: ``out[i] = f(op, a[i],
 * b[i])`` over three float64 arrays of one length. */
static inline PyObject *
elementwise_over(PyObject *const *args, Py_ssize_t nargs,
                 double (*f)(long op, double a, double b))
{
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "elementwise takes 4 arguments");
        return NULL;
    }
    long op = PyLong_AsLong(args[0]);
    if (op == -1 && PyErr_Occurred()) {
        return NULL;
    }
    Rows r[3];
    if (get_all_rows(args + 1, r, 3, 2) < 0) {
        return NULL;
    }
    Py_ssize_t n = r[2].len;
    if (r[0].len != n || r[1].len != n) {
        release(r, 3);
        PyErr_SetString(PyExc_ValueError, "elementwise: shapes differ");
        return NULL;
    }
    const double *a = r[0].data, *b = r[1].data;
    double *out = r[2].data;
    for (Py_ssize_t i = 0; i < n; i++) {
        out[i] = f(op, a[i], b[i]);
    }
    release(r, 3);
    Py_RETURN_NONE;
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
