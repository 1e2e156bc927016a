/* The sensing draws of many worlds in one C call (sandbox/behaviour/sensing.py).
 *
 * Broadcast draws each world's noise, then its packet losses, from the world's own
 * Generator. Generator.standard_normal and Generator.random fill an array with
 * numpy's random C API (random_standard_normal_fill, random_standard_uniform_fill of
 * numpy/random/distributions.h, in the npyrandom library numpy ships for extensions
 * in numpy/random/lib) on the bit generator's bitgen_t, which BitGenerator.capsule
 * holds; this makes the same calls for every world in turn, so each world's stream
 * advances as its Generator methods advance it. It is the compiled path ``draws`` of
 * sandbox/accel.py.
 */

#include "accel.h"
#include "numpy/random/distributions.h"

PyDoc_STRVAR(fill_worlds_doc,
"fill_worlds(capsules, noise, lost) -> None\n"
"\n"
"``capsules`` a list of K bit generators' capsules (``BitGenerator.capsule``):\n"
"fills world w's rows of ``noise`` (K, n, 3) with its standard normals, then of\n"
"``lost`` (K, n) with its uniforms in [0, 1), as ``standard_normal(out=...)`` then\n"
"``random(out=...)`` of its Generator would.");

static PyObject *
fill_worlds(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "fill_worlds takes 3 arguments");
        return NULL;
    }
    PyObject *capsules = args[0];
    if (!PyList_CheckExact(capsules)) {
        PyErr_SetString(PyExc_TypeError, "fill_worlds: capsules must be a list");
        return NULL;
    }
    Rows r[2];
    if (get_all_rows(args + 1, r, 2, 0) < 0) {
        return NULL;
    }
    Py_ssize_t K = PyList_GET_SIZE(capsules);
    Py_ssize_t n = K ? r[1].len / K : 0;
    if (K == 0 || r[1].len != K * n || r[0].len != 3 * K * n) {
        release(r, 2);
        PyErr_SetString(PyExc_ValueError, "fill_worlds: shapes differ");
        return NULL;
    }
    for (Py_ssize_t w = 0; w < K; w++) {
        bitgen_t *bitgen = (bitgen_t *)PyCapsule_GetPointer(
            PyList_GET_ITEM(capsules, w), "BitGenerator");
        if (bitgen == NULL) {
            release(r, 2);
            return NULL;
        }
        random_standard_normal_fill(bitgen, 3 * n, r[0].data + 3 * n * w);
        random_standard_uniform_fill(bitgen, n, r[1].data + n * w);
    }
    release(r, 2);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fill_worlds", (PyCFunction)(void (*)(void))fill_worlds, METH_FASTCALL,
     fill_worlds_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_draws",
    "The sensing draws of many worlds in C (see sandbox/behaviour/sensing.py).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__draws(void)
{
    return PyModule_Create(&module);
}
