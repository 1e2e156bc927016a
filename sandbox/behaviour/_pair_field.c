/* The vehicles' terms of the avoidance field, eqs. (22)-(27), in one C call.
 *
 * sandbox/behaviour/pair_field.py calls this where this optional extension is built
 * (the compiled path ``pair_field`` of sandbox/accel.py). For the candidate pairs of a neighbour search it does what
 * the neighbour list's filter and sandbox.behaviour.recovery.weighted_shift do with
 * numpy for the discontinuous and continuous weights without the tangential term:
 * keep the pairs closer than the search radius, weigh each one and add its terms to
 * both vehicles' sums, each vehicle's terms as numpy's bincount adds them (first
 * the pairs where it comes first, in order, then those where it comes second), with
 * the C library's sqrt.
 */

#include "accel.h"

/* sandbox.model.obstacle_field.MIN_DIST: the least distance of eq. (25) [m]. */
#define MIN_DIST 1e-6

/* alpha of eq. (22) (kind 0: 1 within R) or eq. (27) (kind 1: continuous). */
static inline double
weight(int kind, double dist, double R, double r)
{
    if (kind == 0) {
        return dist < R ? 1.0 : 0.0;
    }
    return clamp(1.0 - (dist - r) / (R - r), 0.0, 1.0);
}

/* One side's distance of eq. (25) from its offset (x, y). */
static inline double
side_distance(double x, double y)
{
    return larger(sqrt(x * x + y * y), MIN_DIST);
}

/* The pairs' terms of the field before beta, added to ``out`` (n, 2), which holds
 * zeros: the candidate pairs ``(ci[k], cj[k])`` of the true positions ``p`` closer
 * than ``radius`` (every candidate's squared distance written to ``dd2``), weighed
 * with ``kind``; ``on`` set where a term weighs above zero. ``q`` (rows of ``qs``
 * values, the position first) the broadcast positions each vehicle sees of the
 * others, or NULL for the true ones. */
static void
add_terms(const double *p, const double *q, int qs, const Py_ssize_t *ci,
          const Py_ssize_t *cj, Py_ssize_t m, double radius, double R, double r,
          int kind, double *out, unsigned char *on, double *dd2)
{
    double limit = radius * radius;
    for (Py_ssize_t k = 0; k < m; k++) { /* the search's filter, on true positions */
        Py_ssize_t i = ci[k], j = cj[k];
        double x = p[2 * i] - p[2 * j], y = p[2 * i + 1] - p[2 * j + 1];
        dd2[k] = x * x + y * y;
    }
    /* Two passes, as bincount adds the terms: each pair's term on its first
     * vehicle, in order, then its term on its second vehicle. */
    for (int side = 0; side < 2; side++) {
        for (Py_ssize_t k = 0; k < m; k++) {
            if (!(dd2[k] < limit)) {
                continue;
            }
            Py_ssize_t i = ci[k], j = cj[k];
            double c0, c1, alpha;
            if (q == NULL) { /* alpha (rel / dist^2), -that on j */
                double x = p[2 * i] - p[2 * j], y = p[2 * i + 1] - p[2 * j + 1];
                double dist = larger(sqrt(dd2[k]), MIN_DIST);
                double dd = dist * dist;
                alpha = weight(kind, dist, R, r);
                c0 = alpha * (x / dd);
                c1 = alpha * (y / dd);
                if (side) {
                    c0 = -c0;
                    c1 = -c1;
                }
            }
            else if (!side) { /* i reads pos[i] - seen[j] */
                double x = p[2 * i] - q[qs * j], y = p[2 * i + 1] - q[qs * j + 1];
                double dist = side_distance(x, y);
                alpha = weight(kind, dist, R, r);
                c0 = alpha * x / (dist * dist);
                c1 = alpha * y / (dist * dist);
            }
            else { /* j reads seen[i] - pos[j]: -alpha rel / dist^2 */
                double x = q[qs * i] - p[2 * j], y = q[qs * i + 1] - p[2 * j + 1];
                double dist = side_distance(x, y);
                alpha = weight(kind, dist, R, r);
                c0 = -alpha * x / (dist * dist);
                c1 = -alpha * y / (dist * dist);
            }
            Py_ssize_t v = side ? j : i;
            out[2 * v] += c0;
            out[2 * v + 1] += c1;
            if (alpha > 0) {
                on[v] = 1;
            }
        }
    }
}

PyDoc_STRVAR(pair_field_doc,
"pair_field(pos, seen, i, j, radius, R, r, kind, shift, active, d2, beta, avoid)\n"
"    -> None\n"
"\n"
"The vehicles' terms of the avoidance field of the candidate pairs ``(i[k], j[k])``\n"
"(intp, in order) of the positions ``pos`` (n, 2): the pairs with ``d2 < radius^2``\n"
"weighed with ``kind`` 0 (discontinuous) or 1 (continuous, inner radius ``r``) and\n"
"added to ``shift`` (n, 2), which must hold zeros; ``active`` (n,) bool set where\n"
"a term weighs above zero; every candidate's squared distance written to ``d2``.\n"
"``seen`` (n, 2): each vehicle sees the other's broadcast position (None: the\n"
"true positions). With ``avoid`` (n,) bool (else None) the field is finished as\n"
"weighted_shift finishes it without static obstacles: ``shift *= beta``, zero and\n"
"inactive where not ``avoid``.");

static PyObject *
pair_field(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 13) {
        PyErr_SetString(PyExc_TypeError, "pair_field takes 13 arguments");
        return NULL;
    }
    double radius = PyFloat_AsDouble(args[4]);
    double R = PyFloat_AsDouble(args[5]);
    double r = PyFloat_AsDouble(args[6]);
    long kind = PyLong_AsLong(args[7]);
    int finish = args[12] != Py_None;
    double beta = finish ? PyFloat_AsDouble(args[11]) : 0.0;
    if (PyErr_Occurred()) {
        return NULL;
    }
    int with_seen = args[1] != Py_None;
    Py_buffer avoid;
    Rows pos, seen, shift, d2;
    Indices ci, cj;
    Py_buffer active;
    int stage = 0; /* what has been acquired, for the release */
    PyObject *result = NULL;
    if (get_rows(args[0], &pos, 0) < 0) goto done;
    stage = 1;
    if (with_seen && get_rows(args[1], &seen, 0) < 0) goto done;
    stage = 2;
    if (get_indices(args[2], &ci) < 0) goto done;
    stage = 3;
    if (get_indices(args[3], &cj) < 0) goto done;
    stage = 4;
    if (get_rows(args[8], &shift, 1) < 0) goto done;
    stage = 5;
    if (get_bytes(args[9], &active, 1) < 0) goto done;
    stage = 6;
    if (get_rows(args[10], &d2, 1) < 0) goto done;
    stage = 7;
    if (finish && get_bytes(args[12], &avoid, 0) < 0) goto done;
    stage = 8;
    Py_ssize_t n = shift.len / 2, m = ci.len;
    if (pos.len != 2 * n || (with_seen && seen.len != 2 * n) || cj.len != m ||
        d2.len != m || active.len != n || active.itemsize != 1 ||
        (finish && (avoid.len != n || avoid.itemsize != 1))) {
        PyErr_SetString(PyExc_ValueError, "pair_field: shapes differ");
        goto done;
    }
    for (Py_ssize_t k = 0; k < m; k++) {
        if (ci.data[k] < 0 || ci.data[k] >= n || cj.data[k] < 0 || cj.data[k] >= n) {
            PyErr_SetString(PyExc_IndexError, "pair_field: a pair out of range");
            goto done;
        }
    }
    add_terms(pos.data, with_seen ? seen.data : NULL, 2, ci.data, cj.data, m,
              radius, R, r, (int)kind, shift.data, (unsigned char *)active.buf,
              d2.data);
    double *out = shift.data;
    unsigned char *on = (unsigned char *)active.buf;
    if (finish) { /* shift *= beta; shift[~avoid] = 0; active &= avoid */
        const unsigned char *may = (const unsigned char *)avoid.buf;
        for (Py_ssize_t v = 0; v < n; v++) {
            out[2 * v] = out[2 * v] * beta;
            out[2 * v + 1] = out[2 * v + 1] * beta;
            if (!may[v]) {
                out[2 * v] = 0.0;
                out[2 * v + 1] = 0.0;
                on[v] = 0;
            }
        }
    }
    result = Py_None;
    Py_INCREF(result);
done:
    if (stage >= 8 && finish) PyBuffer_Release(&avoid);
    if (stage >= 7) PyBuffer_Release(&d2.view);
    if (stage >= 6) PyBuffer_Release(&active);
    if (stage >= 5) PyBuffer_Release(&shift.view);
    if (stage >= 4) PyBuffer_Release(&cj.view);
    if (stage >= 3) PyBuffer_Release(&ci.view);
    if (stage >= 2 && with_seen) PyBuffer_Release(&seen.view);
    if (stage >= 1) PyBuffer_Release(&pos.view);
    return result;
}

PyDoc_STRVAR(shifted_targets_doc,
"shifted_targets(pos, seen, i, j, radius, R, r, kind, beta, avoid, slot, shift,\n"
"                target, active, d2) -> None\n"
"\n"
"The field of pair_field, finished, and the shifted targets of eq. (22) / (26):\n"
"``shift`` (n, 2) is set to the pairs' terms (as pair_field adds them; ``seen``\n"
"None, (n, 2) or (n, 3), the broadcast poses, the position first) times ``beta``\n"
"(one value, or (n,) each row's), zero where not ``avoid`` (n,) bool; ``active``\n"
"(n,) bool to the vehicles with a term above zero that avoid; ``target`` (n, 2) to\n"
"``slot + shift``; ``d2`` to every candidate's squared distance. Each of ``shift``,\n"
"``target``, ``active``, ``d2`` None: a new array (where the module's ALLOCATES).\n"
"Returns ``(target, shift, active, d2)``.");

static PyObject *
shifted_targets(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 15) {
        PyErr_SetString(PyExc_TypeError, "shifted_targets takes 15 arguments");
        return NULL;
    }
    double radius = PyFloat_AsDouble(args[4]);
    double R = PyFloat_AsDouble(args[5]);
    double r = PyFloat_AsDouble(args[6]);
    long kind = PyLong_AsLong(args[7]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    int with_seen = args[1] != Py_None;
    /* float64: pos, seen, beta, slot, shift, target, d2 */
    static const int at[] = {0, 1, 8, 10, 11, 12, 14};
    Rows rows[7];
    int have[7] = {0};
    Indices ci, cj;
    Py_buffer avoid, active;
    int got_i = 0, got_j = 0, got_avoid = 0, got_active = 0;
    PyObject *result = NULL;
    /* the outputs, given or new: shift, target, active, d2 */
    PyObject *out[4] = {NULL, NULL, NULL, NULL};
    static const int out_at[] = {11, 12, 13, 14};
    if (get_indices(args[2], &ci) < 0) goto done;
    got_i = 1;
    if (get_indices(args[3], &cj) < 0) goto done;
    got_j = 1;
    if (get_rows(args[0], &rows[0], 0) < 0) goto done;
    have[0] = 1;
    for (int k = 0; k < 4; k++) {
        PyObject *obj = args[out_at[k]];
        if (obj == Py_None) {
            Py_ssize_t N = rows[0].len / 2;
            out[k] = k < 2    ? new_array(2, N, 2, 0)
                     : k == 2 ? new_array(1, N, 0, 1)
                              : new_array(1, ci.len, 0, 0);
            if (out[k] == NULL) goto done;
        }
        else {
            out[k] = obj;
            Py_INCREF(obj);
        }
    }
    for (int k = 1; k < 7; k++) {
        PyObject *obj = args[at[k]];
        if (at[k] == 11 || at[k] == 12 || at[k] == 14) {
            obj = out[at[k] == 14 ? 3 : at[k] - 11];
        }
        if (obj == Py_None) {
            continue;
        }
        if (get_rows(obj, &rows[k], at[k] >= 11) < 0) goto done;
        have[k] = 1;
    }
    if (get_bytes(args[9], &avoid, 0) < 0) goto done;
    got_avoid = 1;
    if (get_bytes(out[2], &active, 1) < 0) goto done;
    got_active = 1;
    if (!(have[0] && have[2] && have[3] && have[4] && have[5] && have[6])) {
        PyErr_SetString(PyExc_TypeError, "shifted_targets: an array is missing");
        goto done;
    }
    Rows *pos = &rows[0], *seen = &rows[1], *beta = &rows[2], *slot = &rows[3];
    Rows *shift = &rows[4], *target = &rows[5], *d2 = &rows[6];
    Py_ssize_t n = pos->len / 2, m = ci.len;
    int qs = with_seen && seen->len == 3 * n ? 3 : 2;
    if (pos->len != 2 * n || (with_seen && seen->len != qs * n) || cj.len != m ||
        d2->len != m || active.len != n || active.itemsize != 1 ||
        avoid.len != n || avoid.itemsize != 1 || slot->len != 2 * n ||
        shift->len != 2 * n || target->len != 2 * n ||
        (beta->len != 1 && beta->len != n)) {
        PyErr_SetString(PyExc_ValueError, "shifted_targets: shapes differ");
        goto done;
    }
    for (Py_ssize_t k = 0; k < m; k++) {
        if (ci.data[k] < 0 || ci.data[k] >= n || cj.data[k] < 0 || cj.data[k] >= n) {
            PyErr_SetString(PyExc_IndexError, "shifted_targets: a pair out of range");
            goto done;
        }
    }
    double *shifted = shift->data, *goal = target->data;
    const double *s = slot->data, *b = beta->data;
    unsigned char *on = (unsigned char *)active.buf;
    const unsigned char *may = (const unsigned char *)avoid.buf;
    memset(shifted, 0, (size_t)(2 * n) * sizeof(double));
    memset(on, 0, (size_t)n);
    add_terms(pos->data, with_seen ? seen->data : NULL, qs, ci.data, cj.data, m,
              radius, R, r, (int)kind, shifted, on, d2->data);
    for (Py_ssize_t v = 0; v < n; v++) {
        double bv = b[v * beta->step]; /* shift *= beta, eq. (22) / (26) */
        shifted[2 * v] = shifted[2 * v] * bv;
        shifted[2 * v + 1] = shifted[2 * v + 1] * bv;
        if (!may[v]) { /* shift[~avoid] = 0; active &= avoid */
            shifted[2 * v] = 0.0;
            shifted[2 * v + 1] = 0.0;
            on[v] = 0;
        }
        goal[2 * v] = s[2 * v] + shifted[2 * v]; /* target = slot + shift */
        goal[2 * v + 1] = s[2 * v + 1] + shifted[2 * v + 1];
    }
    result = PyTuple_Pack(4, out[1], out[0], out[2], out[3]);
done:
    if (got_active) PyBuffer_Release(&active);
    if (got_avoid) PyBuffer_Release(&avoid);
    if (got_j) PyBuffer_Release(&cj.view);
    if (got_i) PyBuffer_Release(&ci.view);
    for (int k = 0; k < 7; k++) {
        if (have[k]) {
            PyBuffer_Release(&rows[k].view);
        }
    }
    for (int k = 0; k < 4; k++) {
        Py_XDECREF(out[k]);
    }
    return result;
}

static PyMethodDef methods[] = {
    {"pair_field", (PyCFunction)(void (*)(void))pair_field, METH_FASTCALL,
     pair_field_doc},
    {"shifted_targets", (PyCFunction)(void (*)(void))shifted_targets, METH_FASTCALL,
     shifted_targets_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_pair_field",
    "The vehicles' terms of the avoidance field in C (sandbox/behaviour/pair_field.py).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__pair_field(void)
{
    return module_allocating(&module);
}
