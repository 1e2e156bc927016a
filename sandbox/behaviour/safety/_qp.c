/* The exact projection of sandbox/behaviour/safety/qp.py (project) in one C call.
 *
 * qp.py calls this where this optional extension is built and its check passes. For
 * each problem it does what numpy's project does: z0 itself if it keeps every
 * half-plane (within the tolerance); else every candidate (the projections of z0 on
 * the edge lines, then the vertices of each pair of lines in numpy's triu order),
 * the feasible ones kept and the nearest returned (the first on a tie, as argmin).
 * The same IEEE-754 double operations in numpy's order (compiled without fused
 * multiply-adds); the C library is not called.
 */

#include "numpy_rules.h"

/* qp.SINGULAR: below this |determinant| two lines are taken as parallel. */
#define SINGULAR 1e-12

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
        const double *a = A + 2 * m * k, *b = B + m * k;
        double x0 = z0[2 * k], y0 = z0[2 * k + 1];
        int inside = 1;
        for (Py_ssize_t q = 0; q < m; q++) {
            double viol = a[2 * q] * x0 + a[2 * q + 1] * y0 - b[q];
            if (!(viol <= tol)) {
                inside = 0;
                break;
            }
        }
        z[2 * k] = x0;
        z[2 * k + 1] = y0;
        feasible[k] = (unsigned char)inside;
        if (inside) {
            continue;
        }
        double best = INFINITY, bx = x0, by = y0;
        int found = 0;
        /* the candidates in numpy's order: m edges, then the vertices (i < j) */
        Py_ssize_t count = m + m * (m - 1) / 2;
        Py_ssize_t i = 0, j = 0;
        for (Py_ssize_t c = 0; c < count; c++) {
            double cx, cy;
            if (c < m) {
                double ax = a[2 * c], ay = a[2 * c + 1];
                double viol = ax * x0 + ay * y0 - b[c];
                double norm2 = ax * ax + ay * ay;
                double step = norm2 > 0 ? viol / norm2 : NAN;
                cx = x0 - step * ax;
                cy = y0 - step * ay;
            }
            else {
                if (c == m) {
                    i = 0;
                    j = 1;
                }
                const double *a1 = a + 2 * i, *a2 = a + 2 * j;
                double b1 = b[i], b2 = b[j];
                double det = a1[0] * a2[1] - a1[1] * a2[0];
                int good = fabs(det) > SINGULAR;
                det = good ? det : 1.0;
                double vx = (b1 * a2[1] - b2 * a1[1]) / det;
                double vy = (a1[0] * b2 - a2[0] * b1) / det;
                cx = good ? vx : NAN;
                cy = good ? vy : NAN;
                if (++j == m) { /* the next pair */
                    i++;
                    j = i + 1;
                }
            }
            int keeps = 1;
            for (Py_ssize_t q = 0; q < m; q++) {
                double lhs = a[2 * q] * cx + a[2 * q + 1] * cy;
                if (!(lhs - b[q] <= tol)) {
                    keeps = 0;
                    break;
                }
            }
            if (!keeps) {
                continue;
            }
            double dx = cx - x0, dy = cy - y0;
            double dist = dx * dx + dy * dy;
            if (dist < best) { /* argmin: the first of equal distances */
                best = dist;
                bx = cx;
                by = cy;
                found = 1;
            }
        }
        if (found && isfinite(best)) {
            z[2 * k] = bx;
            z[2 * k + 1] = by;
            feasible[k] = 1;
        }
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
