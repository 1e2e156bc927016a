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

PyDoc_STRVAR(law_targets_doc,
"law_targets(kind, delta, n, pose, theta, leader, ref_p, ref_dp, ref_ddp, row,\n"
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
law_targets(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 21) {
        PyErr_SetString(PyExc_TypeError, "law_targets takes 21 arguments");
        return NULL;
    }
    long kind = PyLong_AsLong(args[0]);
    Py_ssize_t n = PyLong_AsSsize_t(args[2]);
    Py_ssize_t leader = PyLong_AsSsize_t(args[5]);
    Py_ssize_t row = PyLong_AsSsize_t(args[9]);
    long rotate = PyLong_AsLong(args[10]);
    double tangent = PyFloat_AsDouble(args[11]);
    double h = PyFloat_AsDouble(args[12]);
    long long count = PyLong_AsLongLong(args[13]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    int has_theta = args[4] != Py_None, has_ref = args[6] != Py_None;
    int has_history = args[14] != Py_None;
    /* float64 arrays: delta, pose, theta, ref_p, ref_dp, ref_ddp, prev_x, prev_v,
     * slot, v_ref, a_ref; absent ones (None) are skipped */
    static const int at[] = {1, 3, 4, 6, 7, 8, 14, 15, 18, 19, 20};
    Rows r[11];
    int have[11] = {0};
    Indices track, cmd;
    int got_track = 0, got_cmd = 0;
    PyObject *result = NULL, *out[3] = {NULL, NULL, NULL};
    for (int k = 0; k < 11; k++) {
        PyObject *obj = args[at[k]];
        if (k >= 8) { /* the outputs: the given arrays, or new ones */
            if (obj == Py_None) {
                out[k - 8] = new_array(2, have[0] ? r[0].len / 2 : 0, 2, 0);
                if (out[k - 8] == NULL) goto done;
            }
            else {
                out[k - 8] = obj;
                Py_INCREF(obj);
            }
            obj = out[k - 8];
        }
        else if (obj == Py_None) {
            continue;
        }
        int writable = at[k] >= 14;
        if (get_rows(obj, &r[k], writable) < 0) goto done;
        have[k] = 1;
    }
    if (get_indices(args[16], &track) < 0) goto done;
    got_track = 1;
    if (get_indices(args[17], &cmd) < 0) goto done;
    got_cmd = 1;
    if (!(have[0] && have[1] && have[8] && have[9] && have[10])) {
        PyErr_SetString(PyExc_TypeError, "law_targets: an array is missing");
        goto done;
    }
    Rows *delta = &r[0], *pose = &r[1], *theta = &r[2];
    Rows *slot = &r[8], *v_ref = &r[9], *a_ref = &r[10];
    Py_ssize_t N = slot->len / 2, K = n > 0 ? N / n : 0;
    int stride = has_theta ? 2 : 3;
    int needs_leader = kind != VIRTUAL;
    int needs_ref = kind == VIRTUAL || kind == LEADER_REF;
    int leader_motion = kind == FIXED || kind == ROTATING;
    Py_ssize_t hist = leader_motion ? 2 * K : 2 * N; /* the history's values */
    int fits = kind >= FIXED && kind <= OWN_ESTIMATE && n > 0 && N == K * n &&
               delta->len == 2 * N && v_ref->len == 2 * N &&
               a_ref->len == 2 * N && pose->len == stride * N &&
               (!has_theta || theta->len == N) &&
               (!needs_leader || (leader >= 0 && leader < n)) &&
               (!needs_ref || has_ref) &&
               has_history == (leader_motion || kind == OWN_ESTIMATE) &&
               (!has_history || (have[7] && r[6].len == hist && r[7].len == hist));
    if (fits && has_ref) {
        Py_ssize_t T = r[3].len / 2;
        fits = have[4] && have[5] && r[4].len == 2 * T && r[5].len == 2 * T &&
               row >= 0 && row < T;
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
    const double *d = delta->data, *ps = pose->data;
    const double *p = has_ref ? r[3].data + 2 * row : NULL;
    const double *dp = has_ref ? r[4].data + 2 * row : NULL;
    const double *ddp = has_ref ? r[5].data + 2 * row : NULL;
    double *s = slot->data, *v = v_ref->data, *a = a_ref->data;
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
            double th = has_theta ? theta->data[w * n + leader] : lp[2];
            c = cos(th);
            sn = sin(th);
        }
        if (leader_motion) { /* eqs. (8)-(9) of the leader's position */
            double x[2] = {lp[0], lp[1]};
            difference(x, 2, count, h, r[6].data + 2 * w, r[7].data + 2 * w, lead_v,
                       lead_a);
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
                a[e] = lead_a[0];
                a[e + 1] = lead_a[1];
            }
            else if (kind != OWN_ESTIMATE) { /* the reference's own derivatives */
                v[e] = dp[0];
                v[e + 1] = dp[1];
                a[e] = ddp[0];
                a[e + 1] = ddp[1];
            }
        }
    }
    if (kind == OWN_ESTIMATE) { /* eqs. (18)-(19) of every slot */
        difference(s, 2 * N, count, h, r[6].data, r[7].data, v, a);
    }
    if (has_ref) { /* the rows that track the reference */
        for (Py_ssize_t k = 0; k < track.len; k++) {
            Py_ssize_t e = 2 * track.data[k];
            s[e] = p[0];
            s[e + 1] = p[1];
            v[e] = dp[0];
            v[e + 1] = dp[1];
            a[e] = ddp[0];
            a[e + 1] = ddp[1];
        }
    }
    for (Py_ssize_t k = 0; k < cmd.len; k++) { /* open loop: no slot */
        Py_ssize_t e = 2 * cmd.data[k];
        s[e] = NAN;
        s[e + 1] = NAN;
    }
    result = Py_BuildValue("(OOOd)", out[0], out[1], out[2], tangent);
done:
    if (got_cmd) PyBuffer_Release(&cmd.view);
    if (got_track) PyBuffer_Release(&track.view);
    for (int k = 0; k < 11; k++) {
        if (have[k]) {
            PyBuffer_Release(&r[k].view);
        }
    }
    for (int k = 0; k < 3; k++) {
        Py_XDECREF(out[k]);
    }
    return result;
}

static PyMethodDef methods[] = {
    {"law_targets", (PyCFunction)(void (*)(void))law_targets, METH_FASTCALL,
     law_targets_doc},
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
