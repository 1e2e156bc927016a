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

/* The arguments of pair_terms, by name (accel.h). */
#define PAIR_TERMS(X)                                                              \
    X(pos, FLOATS, 0)                                                              \
    X(seen, FLOATS, OR_NONE)                                                       \
    X(cand_i, INTPS, 0)                                                            \
    X(cand_j, INTPS, 0)                                                            \
    X(radius, NUMBER, 0)                                                           \
    X(R, NUMBER, 0)                                                                \
    X(r, NUMBER, 0)                                                                \
    X(kind, INTEGER, 0)                                                            \
    X(beta, VALUES, OR_NONE)                                                       \
    X(avoid, BYTES, OR_NONE)                                                       \
    X(slot, FLOATS, OR_NONE)                                                       \
    X(shift, FLOATS, WRITTEN | OR_NONE)                                            \
    X(target, FLOATS, WRITTEN | OR_NONE)                                           \
    X(active, BYTES, WRITTEN | OR_NONE)                                            \
    X(d2, FLOATS, WRITTEN | OR_NONE)
NAMED(pair_terms, PAIR_TERMS)

PyDoc_STRVAR(pair_terms_doc,
"pair_terms(*, pos, seen, cand_i, cand_j, radius, R, r, kind, beta, avoid, slot,\n"
"           shift, target, active, d2) -> (target, shift, active, d2)\n"
"\n"
"The vehicles' terms of the avoidance field of the candidate pairs\n"
"``(cand_i[k], cand_j[k])`` (intp, in order) of the positions ``pos`` (n, 2): the\n"
"pairs with ``d2 < radius^2`` weighed with ``kind`` 0 (discontinuous) or 1\n"
"(continuous, inner radius ``r``), their sums written to ``shift`` (n, 2);\n"
"``active`` (n,) bool set to the vehicles with a term above zero; every\n"
"candidate's squared distance written to ``d2``. ``seen`` (n, 2) or (n, 3): each\n"
"vehicle sees the broadcast positions of the others, the position first (None:\n"
"the true positions). With ``avoid`` (n,) bool the field is finished as\n"
"weighted_shift finishes it without static obstacles: times ``beta`` (one value,\n"
"or (n,) each row's), zero and inactive where not ``avoid``; with ``slot`` (n, 2)\n"
"the shifted targets ``slot + shift`` of eq. (22) / (26) are written to\n"
"``target`` (None returned without ``slot``). Each of ``shift``, ``target``,\n"
"``active``, ``d2`` None: a new array (where the module's ALLOCATES).");

static PyObject *
pair_terms(PyObject *self, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    pair_terms_args a;
    if (parse_named(&pair_terms_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    const Py_ssize_t n = a.pos.len / 2, m = a.cand_i.len;
    const int finish = a.avoid.b != NULL, targets = a.slot.f != NULL;
    if ((a.shift.f == NULL && take_new(&a.shift, new_array(2, n, 2, 0), FLOATS) < 0) ||
        (targets && a.target.f == NULL &&
         take_new(&a.target, new_array(2, n, 2, 0), FLOATS) < 0) ||
        (a.active.b == NULL && take_new(&a.active, new_array(1, n, 0, 1), BYTES) < 0) ||
        (a.d2.f == NULL && take_new(&a.d2, new_array(1, m, 0, 0), FLOATS) < 0)) {
        goto done;
    }
    const int qs = a.seen.f != NULL && a.seen.len == 3 * n ? 3 : 2;
    if (a.pos.len != 2 * n || (a.seen.f && a.seen.len != qs * n) ||
        a.cand_j.len != m || a.d2.len != m || a.active.len != n ||
        a.shift.len != 2 * n || (targets && (a.slot.len != 2 * n || a.target.len != 2 * n)) ||
        (finish && (a.avoid.len != n || a.beta.f == NULL ||
                    (a.beta.len != 1 && a.beta.len != n)))) {
        PyErr_SetString(PyExc_ValueError, "pair_terms: shapes differ");
        goto done;
    }
    const Py_ssize_t *ci = a.cand_i.i, *cj = a.cand_j.i;
    for (Py_ssize_t k = 0; k < m; k++) {
        if (ci[k] < 0 || ci[k] >= n || cj[k] < 0 || cj[k] >= n) {
            PyErr_SetString(PyExc_IndexError, "pair_terms: a pair out of range");
            goto done;
        }
    }
    double *shifted = a.shift.f;
    unsigned char *on = a.active.b;
    memset(shifted, 0, (size_t)(2 * n) * sizeof(double));
    memset(on, 0, (size_t)n);
    add_terms(a.pos.f, a.seen.f, qs, ci, cj, m, a.radius.x, a.R.x, a.r.x,
              (int)a.kind.n, shifted, on, a.d2.f);
    if (finish) {
        const double *b = a.beta.f;
        const unsigned char *may = a.avoid.b;
        for (Py_ssize_t v = 0; v < n; v++) {
            double bv = b[v * a.beta.step]; /* shift *= beta, eq. (22) / (26) */
            shifted[2 * v] = shifted[2 * v] * bv;
            shifted[2 * v + 1] = shifted[2 * v + 1] * bv;
            if (!may[v]) { /* shift[~avoid] = 0; active &= avoid */
                shifted[2 * v] = 0.0;
                shifted[2 * v + 1] = 0.0;
                on[v] = 0;
            }
        }
    }
    if (targets) { /* target = slot + shift */
        const double *s = a.slot.f;
        double *goal = a.target.f;
        for (Py_ssize_t v = 0; v < n; v++) {
            goal[2 * v] = s[2 * v] + shifted[2 * v];
            goal[2 * v + 1] = s[2 * v + 1] + shifted[2 * v + 1];
        }
    }
    result = PyTuple_Pack(4, targets ? a.target.obj : Py_None, a.shift.obj,
                          a.active.obj, a.d2.obj);
done:
    release_named(&pair_terms_signature, (Arg *)&a);
    return result;
}

static PyMethodDef methods[] = {
    {"pair_terms", (PyCFunction)(void (*)(void))pair_terms,
     METH_FASTCALL | METH_KEYWORDS, pair_terms_doc},
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
