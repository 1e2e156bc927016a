/* The built-in formation laws' targets of one control period, eqs. (7)-(20), in
 * one C call.
 *
 * sandbox/model/law_kernel.py calls this where this optional extension is built (the
 * compiled path ``laws`` of sandbox/accel.py). For the K worlds of a loop it does what a built-in law class of
 * sandbox/model/laws.py does with numpy (fixed, rotating, virtual, leader_ref,
 * own_estimate; the offsets turned by the reference's tangent with ``rotate``), and
 * what the loop then does with the law's arrays (sandbox/loop/simulation.py,
 * ``_targets``): the rows that track the reference take the reference's point and
 * derivatives, the commanded rows a NaN slot. The law's backward differences of
 * eqs. (8)-(9) and (18)-(19) advance in place, in the arrays the caller owns. The C
 * library's sin, cos, hypot and atan2.
 */

#include "accel.h"

/* sandbox.model.laws.REST_SPEED: below it the tangent of eq. (15) is kept [m/s]. */
#define REST_SPEED 1e-3

/* The law classes, as sandbox/model/law_kernel.py numbers them. */
enum { FIXED = 0, ROTATING = 1, VIRTUAL = 2, LEADER_REF = 3, OWN_ESTIMATE = 4 };

/* BackwardDifference.update of ``m`` values ``x`` (eqs. (8)-(9), (18)-(19)) on the
 * history ``prev_x``, ``prev_v`` after ``count`` updates: writes x' to ``v`` and
 * x'' to ``a`` (zeros at the first update, x'' zero at the second), then keeps
 * ``x`` and ``v`` as the history. */
static void
difference(const double *x, Py_ssize_t m, long long count, double h, double *prev_x,
           double *prev_v, double *v, double *a)
{
    for (Py_ssize_t e = 0; e < m; e++) {
        double ve = 0.0, ae = 0.0;
        if (count > 0) {
            ve = (x[e] - prev_x[e]) / h; /* eq. (8) / (18) */
            if (count >= 2) {
                ae = (ve - prev_v[e]) / h; /* eq. (9) / (19) */
            }
        }
        v[e] = ve;
        a[e] = ae;
        prev_x[e] = x[e];
        prev_v[e] = ve;
    }
}

/* The arguments of law_targets, by name (accel.h). */
#define LAW_TARGETS(X)                                                             \
    X(kind, INTEGER, 0)                                                            \
    X(delta, FLOATS, 0)                                                            \
    X(n, INTEGER, 0)                                                               \
    X(pose, FLOATS, 0)                                                             \
    X(theta, FLOATS, OR_NONE)                                                      \
    X(leader, INTEGER, 0)                                                          \
    X(ref_p, FLOATS, OR_NONE)                                                      \
    X(ref_dp, FLOATS, OR_NONE)                                                     \
    X(ref_ddp, FLOATS, OR_NONE)                                                    \
    X(row, INTEGER, 0)                                                             \
    X(rotate, INTEGER, 0)                                                          \
    X(tangent, NUMBER, 0)                                                          \
    X(h, NUMBER, 0)                                                                \
    X(count, INTEGER, 0)                                                           \
    X(prev_x, FLOATS, WRITTEN | OR_NONE)                                           \
    X(prev_v, FLOATS, WRITTEN | OR_NONE)                                           \
    X(track, INTPS, 0)                                                             \
    X(commanded, INTPS, 0)                                                         \
    X(slot, FLOATS, WRITTEN | OR_NONE)                                             \
    X(v_ref, FLOATS, WRITTEN | OR_NONE)                                            \
    X(a_ref, FLOATS, WRITTEN | OR_NONE)
NAMED(law_targets, LAW_TARGETS)

PyDoc_STRVAR(law_targets_doc,
"law_targets(*, kind, delta, n, pose, theta, leader, ref_p, ref_dp, ref_ddp, row,\n"
"            rotate, tangent, h, count, prev_x, prev_v, track, commanded, slot,\n"
"            v_ref, a_ref) -> (slot, v_ref, a_ref, tangent)\n"
"\n"
"The targets of a period of the built-in law ``kind`` (0 fixed, 1 rotating, 2\n"
"virtual, 3 leader_ref, 4 own_estimate) for K worlds of ``n`` vehicles: ``delta``\n"
"(K n, 2) the offsets; the leader's pose read at row ``w n + leader`` of ``pose``\n"
"(K n, 2) with ``theta`` (K n,), or of ``pose`` (K n, 3) with ``theta`` None; the\n"
"reference's point and derivatives at row ``row`` of ``ref_p``, ``ref_dp``,\n"
"``ref_ddp`` (T, 2) (None: no reference); ``rotate`` (0 or 1) and the tangent\n"
"angle of eq. (15) last defined [rad]; ``h`` [s]; the backward difference's\n"
"``count`` and history ``prev_x``, ``prev_v`` ((K, 2) of the leader, or (K n, 2) of\n"
"the slots; None for a law without one), advanced in place. Writes ``slot``,\n"
"``v_ref``, ``a_ref`` (K n, 2; each None: a new array, where the module's\n"
"ALLOCATES), then the reference's point and derivatives on the rows ``track``\n"
"(intp) and NaN slots on the rows ``commanded``. Returns the three arrays and the\n"
"tangent angle now.");

static PyObject *
law_targets(PyObject *self, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    law_targets_args a;
    if (parse_named(&law_targets_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    const long kind = (long)a.kind.n;
    const Py_ssize_t n = a.n.n, leader = a.leader.n, row = a.row.n;
    const int rotate = a.rotate.n != 0;
    const long long count = (long long)a.count.n;
    const double h = a.h.x;
    double tangent = a.tangent.x;
    const int has_theta = a.theta.f != NULL, has_ref = a.ref_p.f != NULL;
    const int has_history = a.prev_x.f != NULL;
    const Py_ssize_t N = a.delta.len / 2, K = n > 0 ? N / n : 0;
    Arg *outputs[3] = {&a.slot, &a.v_ref, &a.a_ref};
    for (int k = 0; k < 3; k++) { /* the outputs: the given arrays, or new ones */
        if (outputs[k]->f == NULL &&
            take_new(outputs[k], new_array(2, N, 2, 0), FLOATS) < 0) {
            goto done;
        }
    }
    const Indices track = {.data = a.track.i, .len = a.track.len};
    const Indices cmd = {.data = a.commanded.i, .len = a.commanded.len};
    const Arg *delta = &a.delta, *pose = &a.pose, *theta = &a.theta;
    const int stride = has_theta ? 2 : 3;
    const int needs_leader = kind != VIRTUAL;
    const int needs_ref = kind == VIRTUAL || kind == LEADER_REF;
    const int leader_motion = kind == FIXED || kind == ROTATING;
    const Py_ssize_t hist = leader_motion ? 2 * K : 2 * N; /* the history's values */
    int fits = kind >= FIXED && kind <= OWN_ESTIMATE && n > 0 && N == K * n &&
               delta->len == 2 * N && a.slot.len == 2 * N && a.v_ref.len == 2 * N &&
               a.a_ref.len == 2 * N && pose->len == stride * N &&
               (!has_theta || theta->len == N) &&
               (!needs_leader || (leader >= 0 && leader < n)) &&
               (!needs_ref || has_ref) &&
               has_history == (leader_motion || kind == OWN_ESTIMATE) &&
               (!has_history ||
                (a.prev_v.f && a.prev_x.len == hist && a.prev_v.len == hist));
    if (fits && has_ref) {
        Py_ssize_t T = a.ref_p.len / 2;
        fits = a.ref_dp.f && a.ref_ddp.f && a.ref_dp.len == 2 * T &&
               a.ref_ddp.len == 2 * T && row >= 0 && row < T;
    }
    for (Py_ssize_t k = 0; fits && k < track.len; k++) {
        fits = track.data[k] >= 0 && track.data[k] < N;
    }
    for (Py_ssize_t k = 0; fits && k < cmd.len; k++) {
        fits = cmd.data[k] >= 0 && cmd.data[k] < N;
    }
    if (!fits) {
        PyErr_SetString(PyExc_ValueError, "law_targets: shapes differ");
        goto done;
    }
    const double *d = delta->f, *ps = pose->f;
    const double *p = has_ref ? a.ref_p.f + 2 * row : NULL;
    const double *dp = has_ref ? a.ref_dp.f + 2 * row : NULL;
    const double *ddp = has_ref ? a.ref_ddp.f + 2 * row : NULL;
    double *s = a.slot.f, *v = a.v_ref.f, *acc = a.a_ref.f;
    double *prev_x = a.prev_x.f, *prev_v = a.prev_v.f;
    if (rotate && (kind == VIRTUAL || kind == LEADER_REF)) {
        if (hypot(dp[0], dp[1]) >= REST_SPEED) {
            tangent = atan2(dp[1], dp[0]); /* eq. (15) */
        }
        /* at rest eq. (15) is atan2(0, 0): the last tangent is kept */
    }
    int turned = (rotate && (kind == VIRTUAL || kind == LEADER_REF)) ||
                 kind == ROTATING || kind == OWN_ESTIMATE;
    double ct = turned ? cos(tangent) : 1.0, st = turned ? sin(tangent) : 0.0;
    double lead_v[2] = {0.0, 0.0}, lead_a[2] = {0.0, 0.0};
    for (Py_ssize_t w = 0; w < K; w++) {
        const double *lp = needs_leader ? ps + stride * (w * n + leader) : NULL;
        double c = ct, sn = st;
        if (kind == ROTATING || kind == OWN_ESTIMATE) { /* the leader's heading */
            double th = has_theta ? theta->f[w * n + leader] : lp[2];
            c = cos(th);
            sn = sin(th);
        }
        if (leader_motion) { /* eqs. (8)-(9) of the leader's position */
            double x[2] = {lp[0], lp[1]};
            difference(x, 2, count, h, prev_x + 2 * w, prev_v + 2 * w, lead_v, lead_a);
        }
        for (Py_ssize_t i = 0; i < n; i++) {
            Py_ssize_t e = 2 * (w * n + i);
            double d1 = d[e], d2 = d[e + 1], o1 = d1, o2 = d2;
            if (turned) { /* eqs. (11), (14), (20) */
                o1 = d1 * c - d2 * sn;
                o2 = d2 * c + d1 * sn;
            }
            if (kind == VIRTUAL) { /* eq. (13) */
                s[e] = p[0] + o1;
                s[e + 1] = p[1] + o2;
            }
            else { /* eqs. (7), (10), (16), (20) */
                s[e] = lp[0] + o1;
                s[e + 1] = lp[1] + o2;
            }
            if (leader_motion) {
                v[e] = lead_v[0];
                v[e + 1] = lead_v[1];
                acc[e] = lead_a[0];
                acc[e + 1] = lead_a[1];
            }
            else if (kind != OWN_ESTIMATE) { /* the reference's own derivatives */
                v[e] = dp[0];
                v[e + 1] = dp[1];
                acc[e] = ddp[0];
                acc[e + 1] = ddp[1];
            }
        }
    }
    if (kind == OWN_ESTIMATE) { /* eqs. (18)-(19) of every slot */
        difference(s, 2 * N, count, h, prev_x, prev_v, v, acc);
    }
    if (has_ref) { /* the rows that track the reference */
        for (Py_ssize_t k = 0; k < track.len; k++) {
            Py_ssize_t e = 2 * track.data[k];
            s[e] = p[0];
            s[e + 1] = p[1];
            v[e] = dp[0];
            v[e + 1] = dp[1];
            acc[e] = ddp[0];
            acc[e + 1] = ddp[1];
        }
    }
    for (Py_ssize_t k = 0; k < cmd.len; k++) { /* open loop: no slot */
        Py_ssize_t e = 2 * cmd.data[k];
        s[e] = NAN;
        s[e + 1] = NAN;
    }
    result = Py_BuildValue("(OOOd)", a.slot.obj, a.v_ref.obj, a.a_ref.obj, tangent);
done:
    release_named(&law_targets_signature, (Arg *)&a);
    return result;
}

static PyMethodDef methods[] = {
    {"law_targets", (PyCFunction)(void (*)(void))law_targets,
     METH_FASTCALL | METH_KEYWORDS, law_targets_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_laws",
    "The built-in formation laws' targets in C (sandbox/model/law_kernel.py).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__laws(void)
{
    return module_allocating(&module);
}
