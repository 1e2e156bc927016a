/* The exact projection of sandbox/behaviour/safety/qp.py (project) in one C call.
 *
 * qp.py calls this where this optional extension is built (the compiled path ``qp``
 * of sandbox/accel.py): each problem projected as qp.project_numpy projects it
 * (qp_project.h, shared with _filter.c).
 */

#include "accel.h"
#include "qp_project.h"

PyDoc_STRVAR(project_doc,
"project(z0, a, b, tol, z, feasible) -> None\n"
"\n"
"``z0`` (n, 2), ``a`` (n, m, 2), ``b`` (n, m) float64; writes the nearest point of\n"
"each polygon to ``z`` (n, 2) (``z0`` where it is empty) and ``feasible`` (n,) bool.");

static PyObject *
project(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "project takes 6 arguments");
        return NULL;
    }
    double tol = PyFloat_AsDouble(args[3]);
    if (tol == -1.0 && PyErr_Occurred()) {
        return NULL;
    }
    Rows r[4];
    Py_buffer ok;
    int got = 0, got_ok = 0;
    PyObject *result = NULL;
    const int at[] = {0, 1, 2, 4};
    for (int k = 0; k < 4; k++) {
        if (get_rows(args[at[k]], &r[k], k == 3) < 0) goto done;
        got++;
    }
    if (PyObject_GetBuffer(args[5], &ok, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE) < 0)
        goto done;
    got_ok = 1;
    Py_ssize_t n = r[0].len / 2;
    Py_ssize_t m = n ? r[2].len / n : 0;
    if (r[0].len != 2 * n || r[2].len != n * m || r[1].len != 2 * n * m ||
        r[3].len != 2 * n || ok.len != n || ok.itemsize != 1) {
        PyErr_SetString(PyExc_ValueError, "project: shapes differ");
        goto done;
    }
    const double *z0 = r[0].data, *A = r[1].data, *B = r[2].data;
    double *z = r[3].data;
    unsigned char *feasible = ok.buf;
    for (Py_ssize_t k = 0; k < n; k++) {
        feasible[k] = (unsigned char)project_one(A + 2 * m * k, B + m * k, m, z0[2 * k],
                                                 z0[2 * k + 1], tol, z + 2 * k);
    }
    result = Py_None;
    Py_INCREF(result);
done:
    release(r, got);
    if (got_ok) {
        PyBuffer_Release(&ok);
    }
    return result;
}

static PyMethodDef methods[] = {
    {"project", (PyCFunction)(void (*)(void))project, METH_FASTCALL, project_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_qp",
    "The exact projection of the safety filter's QPs in C (see qp.py).", -1, methods,
};

PyMODINIT_FUNC
PyInit__qp(void)
{
    return PyModule_Create(&module);
}
