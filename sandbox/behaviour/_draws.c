/* The uniform draws of many generators in one C call (sandbox/behaviour/sensing.py).
 *
 * StackedBroadcast draws each world's packet losses from the world's own generator.
 * numpy's Generator.random fills its array with the bit generator's next_double, one
 * element after the other; this does the same for every world, through the function
 * and the state numpy's ctypes interface gives (BitGenerator.ctypes), so each world's
 * stream advances as Generator.random advances it and gives the same numbers.
 * sensing.py checks that on a copy of a generator before it uses this.
 */

#include "numpy_rules.h"
#include <stdint.h>

typedef double (*next_double_t)(void *);

PyDoc_STRVAR(uniform_rows_doc,
"uniform_rows(states, functions, out) -> None\n"
"\n"
"``states`` and ``functions`` (K,) uintp: each world's bit generator state and its\n"
"next_double; fills row w of ``out`` (K, n) float64 from world w's stream.");

static PyObject *
uniform_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "uniform_rows takes 3 arguments");
        return NULL;
    }
    Py_buffer st, fn;
    Rows out;
    if (PyObject_GetBuffer(args[0], &st, PyBUF_C_CONTIGUOUS) < 0) {
        return NULL;
    }
    if (PyObject_GetBuffer(args[1], &fn, PyBUF_C_CONTIGUOUS) < 0) {
        PyBuffer_Release(&st);
        return NULL;
    }
    if (get_rows(args[2], &out, 1) < 0) {
        PyBuffer_Release(&fn);
        PyBuffer_Release(&st);
        return NULL;
    }
    Py_ssize_t K = st.len / (Py_ssize_t)sizeof(uintptr_t);
    if (st.itemsize != (Py_ssize_t)sizeof(uintptr_t) || fn.len != st.len ||
        fn.itemsize != st.itemsize || K == 0 || out.len % K != 0) {
        PyBuffer_Release(&out.view);
        PyBuffer_Release(&fn);
        PyBuffer_Release(&st);
        PyErr_SetString(PyExc_ValueError, "uniform_rows: shapes differ");
        return NULL;
    }
    Py_ssize_t n = out.len / K;
    const uintptr_t *states = st.buf, *functions = fn.buf;
    for (Py_ssize_t w = 0; w < K; w++) {
        next_double_t next = (next_double_t)functions[w];
        void *state = (void *)states[w];
        double *row = out.data + n * w;
        for (Py_ssize_t i = 0; i < n; i++) {
            row[i] = next(state);
        }
    }
    PyBuffer_Release(&out.view);
    PyBuffer_Release(&fn);
    PyBuffer_Release(&st);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"uniform_rows", (PyCFunction)(void (*)(void))uniform_rows, METH_FASTCALL,
     uniform_rows_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_draws",
    "The uniform draws of many generators in C (see sandbox/behaviour/sensing.py).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__draws(void)
{
    return PyModule_Create(&module);
}
