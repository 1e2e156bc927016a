/* What the compiled paths share: named arguments, numpy's arrays read and made, a
 * few plain helpers.
 *
 * Included by every extension of sandbox/accel.py's registry: an entry point's
 * named arguments parsed once into a struct (NAMED, parse_named); a contiguous
 * float64 array (or one value for every row), a contiguous intp index array and a
 * contiguous array of one-byte elements, read from any object with the buffer
 * interface (an ndarray through numpy's C API where the build has its headers),
 * and new arrays made through numpy's C API; the larger and the smaller of two
 * numbers, a clamp, and an angle wrapped around the circle.
 */

#ifndef SANDBOX_ACCEL_H
#define SANDBOX_ACCEL_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
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
    npy_intp size = 1; /* PyArray_SIZE without its call through numpy's table */
    const npy_intp *dims = PyArray_DIMS(a);
    for (int d = PyArray_NDIM(a) - 1; d >= 0; d--) {
        size *= dims[d];
    }
    *count = size;
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

/* ------------------------------------------------------------ named arguments
 *
 * An entry point that reads many arrays takes every argument by name (a keyword,
 * none by position) and parses them once into a struct with a field for each. Its
 * arguments are listed once, as an X-macro of (name, kind, flags) from which NAMED
 * makes both the struct (``function_args``) and the table that parse_named reads:
 *
 *     #define MOTOR_LIMITS(X) X(command, FLOATS, 0) X(force, FLOATS, WRITTEN)
 *     NAMED(motor_limits, MOTOR_LIMITS)
 *
 *     motor_limits_args a;
 *     if (parse_named(&motor_limits_signature, args, nargs, kwnames, (Arg *)&a) < 0)
 *         return NULL;
 *     ... a.command.f[0], a.command.len, a.force.f ...
 *     release_named(&motor_limits_signature, (Arg *)&a);
 *
 * (the entry point is METH_FASTCALL | METH_KEYWORDS). A call from Python names its
 * keywords in the order of the list, where each is found by one comparison of
 * pointers (the names are interned strings on both sides); any other order is
 * found by the names' text. A missing argument, an unknown one, an argument by
 * position, or an array of another type raises TypeError naming the function and
 * the argument, before anything is written.
 */

/* What an argument is. */
enum {
    FLOATS,  /* a C-contiguous float64 array (one element: one value for every row) */
    VALUES,  /* FLOATS, or a number (one value for every row) */
    BYTES,   /* a C-contiguous array of one-byte elements (numpy's bool or int8) */
    INTPS,   /* a C-contiguous intp array */
    INT64S,  /* a C-contiguous int64 array */
    NUMBER,  /* a real number, read as a double */
    INTEGER, /* an integer (a bool, numpy's integers), read as a Py_ssize_t */
    OBJECT   /* any object, as it is */
};

/* An argument's flags: an array written to; None allowed (no data, length 0). */
#define WRITTEN 1
#define OR_NONE 2

/* One argument of an entry point. */
typedef struct {
    const char *name;
    int kind, flags;
} Param;

/* One argument as parsed. */
typedef struct {
    PyObject *obj;  /* as passed (borrowed), or the array made (take_new) */
    union {         /* the data of an array (NULL for None) */
        void *data;
        double *f;
        unsigned char *b;
        Py_ssize_t *i;
        int64_t *q;
    };
    Py_ssize_t len;  /* elements of an array */
    Py_ssize_t step; /* 1, or 0 for a float64 array of one element */
    double x;        /* NUMBER */
    Py_ssize_t n;    /* INTEGER */
    PyObject *made;  /* an array made by the call (take_new), owned */
    Py_buffer view;  /* held where read through the buffer interface */
} Arg;

/* An entry point's arguments: its name, their table and their interned names. */
typedef struct {
    const char *function;
    int count;
    const Param *params;
    PyObject **names; /* interned at the first call */
} Signature;

#define NAMED_FIELD(name, kind, flags) Arg name;
#define NAMED_PARAM(name, kind, flags) {#name, kind, flags},
#define NAMED(function, LIST)                                                       \
    typedef struct {                                                                \
        LIST(NAMED_FIELD)                                                           \
    } function##_args;                                                              \
    static const Param function##_params[] = {LIST(NAMED_PARAM)};                   \
    static PyObject *function##_names[sizeof(function##_params) / sizeof(Param)];   \
    static Signature function##_signature = {                                       \
        #function, (int)(sizeof(function##_params) / sizeof(Param)),               \
        function##_params, function##_names};

/* The type of an array ``kind`` for the messages. */
static inline const char *
kind_text(int kind)
{
    switch (kind) {
    case FLOATS:
    case VALUES: return "a C-contiguous float64 array";
    case BYTES: return "a C-contiguous bool array";
    case INTPS: return "a C-contiguous intp array";
    default: return "a C-contiguous int64 array";
    }
}

/* The array ``obj`` of ``p->kind`` into ``arg`` through the buffer interface (held
 * in arg->view): any object that exports a buffer of the element type. */
static int
take_buffer(const char *function, const Param *p, Arg *arg, PyObject *obj)
{
    int writable = (p->flags & WRITTEN) != 0;
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, &arg->view, flags) < 0) {
        return -1;
    }
    const char *f = arg->view.format ? arg->view.format : "B";
    Py_ssize_t size = arg->view.itemsize;
    int ok;
    switch (p->kind) {
    case FLOATS:
    case VALUES: ok = size == 8 && strcmp(f, "d") == 0; break;
    case BYTES: ok = size == 1; break;
    case INTPS:
        ok = size == (Py_ssize_t)sizeof(Py_ssize_t) &&
             (strcmp(f, "l") == 0 || strcmp(f, "q") == 0 || strcmp(f, "n") == 0);
        break;
    default: ok = size == 8 && (strcmp(f, "l") == 0 || strcmp(f, "q") == 0); break;
    }
    if (!ok) {
        PyBuffer_Release(&arg->view);
        arg->view.obj = NULL;
        PyErr_Format(PyExc_TypeError, "%s: %s: expected %s", function, p->name,
                     kind_text(p->kind));
        return -1;
    }
    arg->data = arg->view.buf;
    arg->len = arg->view.len / size;
    arg->step = arg->len == 1 && (p->kind == FLOATS || p->kind == VALUES) ? 0 : 1;
    return 0;
}

/* The array ``obj`` of ``kind`` into ``arg``: through numpy's C API where it can
 * (nothing held; the common case, inline), else the buffer interface. */
static inline int
take_array(const char *function, const Param *p, Arg *arg, PyObject *obj)
{
#ifdef SANDBOX_NUMPY_API
    int writable = (p->flags & WRITTEN) != 0;
    Py_ssize_t count;
    void *data = NULL;
    switch (p->kind) {
    case FLOATS:
    case VALUES: data = numpy_data(obj, NPY_DOUBLE, writable, &count); break;
    case BYTES:
        data = numpy_data(obj, NPY_BOOL, writable, &count);
        if (data == NULL) {
            data = numpy_data(obj, NPY_INT8, writable, &count);
        }
        break;
    case INTPS: data = numpy_data(obj, NPY_INTP, writable, &count); break;
    default: data = numpy_data(obj, NPY_INT64, writable, &count); break;
    }
    if (data != NULL) {
        arg->data = data;
        arg->len = count;
        arg->step = count == 1 && (p->kind == FLOATS || p->kind == VALUES) ? 0 : 1;
        return 0;
    }
#endif
    return take_buffer(function, p, arg, obj);
}

/* Argument ``k`` of ``sig`` from ``obj``: an array, a number, an integer or an
 * object (None left as no data where allowed). */
static inline int
take_arg(const Signature *sig, int k, Arg *arg, PyObject *obj)
{
    const Param *p = &sig->params[k];
    arg->obj = obj;
    if (obj == Py_None && (p->flags & OR_NONE)) {
        return 0;
    }
    switch (p->kind) {
    case NUMBER:
        arg->x = PyFloat_AsDouble(obj);
        if (arg->x == -1.0 && PyErr_Occurred()) {
            break;
        }
        return 0;
    case INTEGER:
        arg->n = PyNumber_AsSsize_t(obj, PyExc_OverflowError);
        if (arg->n == -1 && PyErr_Occurred()) {
            break;
        }
        return 0;
    case OBJECT: return 0;
    case VALUES:
        if (PyFloat_Check(obj) || PyLong_Check(obj)) { /* one value for every row */
            arg->x = PyFloat_AsDouble(obj);
            if (arg->x == -1.0 && PyErr_Occurred()) {
                return -1;
            }
            arg->f = &arg->x;
            arg->len = 1;
            arg->step = 0;
            return 0;
        }
        return take_array(sig->function, p, arg, obj);
    default: return take_array(sig->function, p, arg, obj);
    }
    PyErr_Format(PyExc_TypeError, "%s: %s: expected %s, got %R", sig->function,
                 p->name, p->kind == NUMBER ? "a number" : "an integer", obj);
    return -1;
}

/* The interned names of ``sig`` (made at its first call). */
static inline int
intern_names(Signature *sig)
{
    if (sig->names[sig->count - 1] != NULL) {
        return 0;
    }
    for (int k = 0; k < sig->count; k++) {
        if (sig->names[k] == NULL) {
            sig->names[k] = PyUnicode_InternFromString(sig->params[k].name);
            if (sig->names[k] == NULL) {
                return -1;
            }
        }
    }
    return 0;
}

/* Which argument of ``sig`` the keyword ``key`` names, or -1. */
static inline int
find_name(const Signature *sig, PyObject *key)
{
    for (int k = 0; k < sig->count; k++) {
        if (key == sig->names[k]) {
            return k;
        }
    }
    for (int k = 0; k < sig->count; k++) {
        if (PyUnicode_Check(key) &&
            PyUnicode_CompareWithASCIIString(key, sig->params[k].name) == 0) {
            return k;
        }
    }
    return -1;
}

/* Release what ``out`` holds (the buffers read, the arrays made). */
static inline void
release_named(const Signature *sig, Arg *out)
{
    for (int k = 0; k < sig->count; k++) {
        if (out[k].view.obj != NULL) {
            PyBuffer_Release(&out[k].view);
        }
        Py_CLEAR(out[k].made);
    }
}

/* Every argument of ``sig`` before anything is read (release_named is safe). */
static inline void
clear_named(const Signature *sig, Arg *out)
{
    for (int k = 0; k < sig->count; k++) {
        out[k].obj = NULL;
        out[k].data = NULL;
        out[k].len = 0;
        out[k].step = 1;
        out[k].made = NULL;
        out[k].view.obj = NULL;
    }
}

/* The keyword arguments of a METH_FASTCALL | METH_KEYWORDS call into ``out`` (an
 * array of sig->count Args: the struct NAMED made). Every argument must be given
 * but those allowed None, which may be left out. On an error nothing is held. */
static inline int
parse_named(Signature *sig, PyObject *const *args, Py_ssize_t nargs,
            PyObject *kwnames, Arg *out)
{
    clear_named(sig, out);
    if (nargs != 0) {
        PyErr_Format(PyExc_TypeError, "%s takes keyword arguments only",
                     sig->function);
        return -1;
    }
    if (intern_names(sig) < 0) {
        return -1;
    }
    Py_ssize_t given = kwnames == NULL ? 0 : PyTuple_GET_SIZE(kwnames);
    for (Py_ssize_t g = 0; g < given; g++) {
        PyObject *key = PyTuple_GET_ITEM(kwnames, g);
        int k = g < sig->count && key == sig->names[g] ? (int)g : find_name(sig, key);
        if (k < 0) {
            PyErr_Format(PyExc_TypeError, "%s: no argument %R", sig->function, key);
            return -1;
        }
        out[k].obj = args[g];
    }
    for (int k = 0; k < sig->count; k++) {
        PyObject *obj = out[k].obj;
        if (obj == NULL) {
            if (!(sig->params[k].flags & OR_NONE)) {
                PyErr_Format(PyExc_TypeError, "%s: missing argument '%s'",
                             sig->function, sig->params[k].name);
                release_named(sig, out);
                return -1;
            }
            obj = Py_None;
        }
        if (take_arg(sig, k, &out[k], obj) < 0) {
            release_named(sig, out);
            return -1;
        }
    }
    return 0;
}

/* The attributes of ``obj`` named by ``sig`` into ``out``, as parse_named reads
 * arguments (a struct of arrays, e.g. a dataclass, read by name). ``obj`` holds
 * the arrays while they are read. */
static inline int
parse_attributes(Signature *sig, PyObject *obj, Arg *out)
{
    clear_named(sig, out);
    if (intern_names(sig) < 0) {
        return -1;
    }
    for (int k = 0; k < sig->count; k++) {
        PyObject *value = PyObject_GetAttr(obj, sig->names[k]);
        if (value == NULL) {
            release_named(sig, out);
            return -1;
        }
        int failed = take_arg(sig, k, &out[k], value) < 0;
        Py_DECREF(value); /* ``obj`` keeps it */
        if (failed) {
            release_named(sig, out);
            return -1;
        }
    }
    return 0;
}

/* ``arg`` (given None) takes the new array ``made`` of ``kind`` (FLOATS or BYTES),
 * an output the call makes: its data read, the array owned by ``arg`` (released
 * with the arguments; a result that returns it takes a reference of its own). */
static inline int
take_new(Arg *arg, PyObject *made, int kind)
{
    if (made == NULL) {
        return -1;
    }
    const Param p = {"output", kind, WRITTEN};
    arg->made = made;
    arg->obj = made;
    return take_array("take_new", &p, arg, made);
}

#endif
