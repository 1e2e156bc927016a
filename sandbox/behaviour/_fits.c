/* The closed-form estimates of the braked-stop fits (sandbox/behaviour/tracks.py).
 *
 * tracks.stop_estimates calls this where this optional extension is built: every
 * row's sum of squares of the braked-stop model over the grid of speeds and onsets,
 * from prefix sums of t^q and s t^q, as the numpy function computes it (the same
 * formula in the same order). The estimates only choose which rows the fit
 * evaluates: each is trusted within a margin 10^5 times its rounding bound, so any
 * rounding of the same formula chooses rows among which the least sum is the same
 * (tracks.py's module docstring).
 */

#include "numpy_rules.h"

/* numpy.searchsorted(t, x, side="left"): the first i with t[i] >= x (t sorted). */
static inline Py_ssize_t
search_left(const double *t, Py_ssize_t m, double x)
{
    Py_ssize_t lo = 0, hi = m;
    while (lo < hi) {
        Py_ssize_t mid = lo + (hi - lo) / 2;
        if (t[mid] < x) {
            lo = mid + 1;
        }
        else {
            hi = mid;
        }
    }
    return lo;
}

PyDoc_STRVAR(stop_estimates_doc,
"stop_estimates(t, s, v, brake, s1, s2, est) -> None\n"
"\n"
"``t``, ``s`` (m,) the track (times from 0, increasing), ``v`` (S,) the speeds,\n"
"``brake`` > 0, ``s1`` and ``s2`` the sums of s and s^2: writes every row's\n"
"estimate to ``est`` (S, m).");

static PyObject *
stop_estimates(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "stop_estimates takes 7 arguments");
        return NULL;
    }
    double brake = PyFloat_AsDouble(args[3]);
    double s1 = PyFloat_AsDouble(args[4]);
    double s2 = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    Rows r[4];
    int got = 0;
    const int at[] = {0, 1, 2, 6};
    for (int k = 0; k < 4; k++) {
        if (get_rows(args[at[k]], &r[k], k == 3) < 0) {
            release(r, got);
            return NULL;
        }
        got++;
    }
    Py_ssize_t m = r[0].len, speeds = r[2].len;
    if (r[1].len != m || r[3].len != speeds * m || m < 1) {
        release(r, got);
        PyErr_SetString(PyExc_ValueError, "stop_estimates: shapes differ");
        return NULL;
    }
    const double *t = r[0].data, *s = r[1].data, *v = r[2].data;
    double *est = r[3].data;
    double *prefix = PyMem_Malloc(sizeof(double) * 8 * (size_t)(m + 1));
    if (prefix == NULL) {
        release(r, got);
        return PyErr_NoMemory();
    }
    /* prefix[q][k]: the sum of the first k terms of t^q (q < 5), s t^(q - 5) */
    for (int q = 0; q < 8; q++) {
        double *p = prefix + q * (m + 1);
        p[0] = 0.0;
        for (Py_ssize_t k = 0; k < m; k++) {
            double power = pow(t[k], (double)(q < 5 ? q : q - 5));
            p[k + 1] = p[k] + (q < 5 ? power : power * s[k]);
        }
    }
#define P(q, k) prefix[(q) * (m + 1) + (k)]
    double a = -0.5 * brake;
    for (Py_ssize_t row = 0; row < speeds; row++) {
        double vv = v[row], length = vv / brake;
        for (Py_ssize_t j = 0; j < m; j++) {
            double tau = t[j];
            Py_ssize_t onset = j + 1;
            Py_ssize_t end = search_left(t, m, tau + length);
            if (end < onset) {
                end = onset;
            }
            double d[8];
            for (int q = 0; q < 8; q++) {
                d[q] = P(q, end) - P(q, onset);
            }
            double r0 = d[0], r1 = d[1], r2 = d[2], r3 = d[3], r4 = d[4];
            double q0 = d[5], q1 = d[6], q2 = d[7];
            double b = vv + brake * tau;
            double c = -0.5 * brake * tau * tau;
            double rest = vv * tau + 0.5 * vv * length;
            double left = (double)(m - end);
            double sum_m = vv * P(1, onset) + (a * r2 + b * r1 + c * r0) + rest * left;
            double sum_mm = vv * vv * P(2, onset) +
                            (a * a * r4 + 2.0 * a * b * r3 + (b * b + 2.0 * a * c) * r2) +
                            (2.0 * b * c * r1 + c * c * r0) + rest * rest * left;
            double sum_sm = vv * P(6, onset) + (a * q2 + b * q1 + c * q0) +
                            rest * (s1 - P(5, end));
            double miss = s1 - sum_m;
            est[row * m + j] = s2 - 2.0 * sum_sm + sum_mm - miss * miss / (double)m;
        }
    }
#undef P
    PyMem_Free(prefix);
    release(r, got);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"stop_estimates", (PyCFunction)(void (*)(void))stop_estimates, METH_FASTCALL,
     stop_estimates_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_fits",
    "The braked-stop fits' estimates in C (see sandbox/behaviour/tracks.py).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__fits(void)
{
    return PyModule_Create(&module);
}
