/* The divergence check's fast path (sandbox/loop/divergence.py) in one C call.
 *
 * Whether a fleet is clearly healthy: every position within the bound, every heading
 * finite, every speed and extension squared within the bound (a NaN fails every
 * comparison, as it fails numpy's reductions). Only a yes or a no: the slow path,
 * in numpy, finds the vehicle and the reason.
 */

#include "numpy_rules.h"

PyDoc_STRVAR(healthy_doc,
"healthy(pos, theta, vel, chi, bound, speed2) -> bool\n"
"\n"
"``pos``, ``vel``, ``chi`` (n, 2), ``theta`` (n,): |pos| <= bound, |theta| < inf,\n"
"|vel|^2 and |chi|^2 <= speed2, each squared norm as x * x + y * y.");

static PyObject *
healthy(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "healthy takes 6 arguments");
        return NULL;
    }
    double bound = PyFloat_AsDouble(args[4]);
    double speed2 = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    Rows r[4];
    int got = 0;
    for (int k = 0; k < 4; k++) {
        if (get_rows(args[k], &r[k], 0) < 0) {
            release(r, got);
            return NULL;
        }
        got++;
    }
    Py_ssize_t n = r[1].len;
    if (r[0].len != 2 * n ||
        r[2].len != 2 * n || r[3].len != 2 * n) {
        release(r, got);
        PyErr_SetString(PyExc_ValueError, "healthy: shapes differ");
        return NULL;
    }
    const double *pos = r[0].data, *theta = r[1].data;
    const double *vel = r[2].data, *chi = r[3].data;
    int ok = 1;
    for (Py_ssize_t i = 0; i < n && ok; i++) {
        const double *p = pos + 2 * i, *v = vel + 2 * i, *c = chi + 2 * i;
        ok = fabs(p[0]) <= bound && fabs(p[1]) <= bound && fabs(theta[i]) < INFINITY &&
             v[0] * v[0] + v[1] * v[1] <= speed2 && c[0] * c[0] + c[1] * c[1] <= speed2;
    }
    release(r, got);
    return PyBool_FromLong(ok);
}

static PyMethodDef methods[] = {
    {"healthy", (PyCFunction)(void (*)(void))healthy, METH_FASTCALL, healthy_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_divergence",
    "The divergence check's fast path in C (see sandbox/loop/divergence.py).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__divergence(void)
{
    return PyModule_Create(&module);
}
