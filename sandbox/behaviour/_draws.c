/* The draws of many generators in one C call (sandbox/behaviour/sensing.py).
 *
 * StackedBroadcast draws each world's noise and packet losses from the world's own
 * generator. numpy's Generator.standard_normal and Generator.random fill their arrays
 * by numpy's own C functions (random_standard_normal_fill, random_standard_uniform_fill,
 * which numpy's random module exports) from the bit generator's bitgen_t (its
 * capsule); this calls the same function for every world in turn, so each world's
 * stream advances as the Generator method advances it and gives the same numbers.
 * sensing.py finds the functions, and checks them on copies of a generator, before it
 * uses this.
 */

#include "numpy_rules.h"
#include <stdint.h>

/* numpy's fill functions: random_standard_normal_fill, random_standard_uniform_fill. */
typedef void (*fill_t)(void *, Py_ssize_t, double *);

PyDoc_STRVAR(fill_rows_doc,
"fill_rows(fill, bitgens, out) -> None\n"
"\n"
"``fill`` the address of one of numpy's fill functions, ``bitgens`` (K,) uintp each\n"
"world's bitgen_t (its BitGenerator's capsule): fills row w of ``out`` (K, m)\n"
"float64 from world w's stream, as ``Generator`` fills an array.");

static PyObject *
fill_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "fill_rows takes 3 arguments");
        return NULL;
    }
    void *address = PyLong_AsVoidPtr(args[0]);
    if (address == NULL) {
        if (!PyErr_Occurred()) {
            PyErr_SetString(PyExc_ValueError, "fill_rows: no function");
        }
        return NULL;
    }
    Py_buffer bg;
    Rows out;
    if (PyObject_GetBuffer(args[1], &bg, PyBUF_C_CONTIGUOUS) < 0) {
        return NULL;
    }
    if (get_rows(args[2], &out, 1) < 0) {
        PyBuffer_Release(&bg);
        return NULL;
    }
    Py_ssize_t K = bg.len / (Py_ssize_t)sizeof(uintptr_t);
    if (bg.itemsize != (Py_ssize_t)sizeof(uintptr_t) || K == 0 || out.len % K != 0) {
        PyBuffer_Release(&out.view);
        PyBuffer_Release(&bg);
        PyErr_SetString(PyExc_ValueError, "fill_rows: shapes differ");
        return NULL;
    }
    Py_ssize_t m = out.len / K;
    fill_t fill = (fill_t)address;
    const uintptr_t *bitgens = bg.buf;
    for (Py_ssize_t w = 0; w < K; w++) {
        fill((void *)bitgens[w], m, out.data + m * w);
    }
    PyBuffer_Release(&out.view);
    PyBuffer_Release(&bg);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fill_rows", (PyCFunction)(void (*)(void))fill_rows, METH_FASTCALL,
     fill_rows_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_draws",
    "The draws of many generators in C (see sandbox/behaviour/sensing.py).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__draws(void)
{
    return PyModule_Create(&module);
}
