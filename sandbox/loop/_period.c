/* Pieces of the loop's period in one C call each.
 *
 * healthy: the divergence check's fast path (sandbox/loop/divergence.py), whether a
 * fleet is clearly healthy: every position within the bound, every heading finite,
 * every speed and extension squared within the bound (a NaN fails every
 * comparison). Only a yes or a no: the slow path, in numpy, finds the vehicle and
 * the reason.
 *
 * buffer_period: what the loop metrics copy of a period into their buffers
 * (sandbox/loop/tally.py, LoopTally._buffer): the pairs' squared distances, the
 * commands, the velocities, the free flags and the commanded velocities along the
 * mean heading, with the C library's sin and cos.
 *
 * record_sample: a sample of every world into the record's buffers
 * (sandbox/loop/recording.py, WorldsRecorder.append): copies only.
 *
 * read_state: the bodies' rows split into positions, headings, velocities and the
 * motors' measured velocities (sandbox/loop/stepping.py, WorldsPhysics.read):
 * copies only.
 *
 * command_rows: the motors' commands of a period from the loop metrics' velocities
 * along the mean heading (WorldsPhysics.advance): copies only.
 *
 * flush_periods: the loop metrics' buffered periods accounted for at once
 * (sandbox/loop/tally.py, LoopTally.flush): the efforts summed period after period,
 * the extremes and the counts.
 *
 * Where they compute, the numbers agree with the numpy path within the tolerance
 * of sandbox/accel.py (this is the compiled path ``period``).
 */

#include "accel.h"

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
    if (get_all_rows(args, r, 4, 4) < 0) {
        return NULL;
    }
    int got = 4;
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

PyDoc_STRVAR(buffer_period_doc,
"buffer_period(pos, i, j, v1, v2, vel, contact, theta, h, d2, v, vel_out, free,\n"
"              cmd[, d2_known]) -> None\n"
"\n"
"For N vehicles: ``pos``, ``vel`` (N, 2), ``v1``, ``v2``, ``theta`` (N,), ``contact``\n"
"(N,) bool, the pairs ``i``, ``j`` (intp, each world's rows from 0, P of them) or\n"
"None; writes ``d2`` (K, P) (where ``i`` is given), ``v`` (2, N), ``vel_out``\n"
"(N, 2), ``free`` (N,) bool and ``cmd`` (N, 2), ``v1 (cos, sin)(theta + v2 h / 2)``;\n"
"without pairs, ``d2_known`` (K P) if given is copied into ``d2``.");

static PyObject *
buffer_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 14 && nargs != 15) {
        PyErr_SetString(PyExc_TypeError, "buffer_period takes 14 or 15 arguments");
        return NULL;
    }
    double h = PyFloat_AsDouble(args[8]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    int pairs = args[1] != Py_None;
    int known = !pairs && nargs == 15 && args[14] != Py_None; /* d2 given: copied */
    Rows given;
    memset(&given.view, 0, sizeof(Py_buffer));
    /* float arrays: pos, v1, v2, vel, theta, d2, v, vel_out, cmd */
    static const int at[] = {0, 3, 4, 5, 7, 9, 10, 11, 13};
    Rows r[9];
    Indices ib, jb;
    Py_buffer cb, fb;
    int got = 0, got_i = 0, got_j = 0, got_c = 0, got_f = 0;
    PyObject *result = NULL;
    if (known && get_rows(args[14], &given, 0) < 0) goto done;
    for (int k = 0; k < 9; k++) {
        if (at[k] == 9 && !pairs && !known) {
            r[k].len = 0;
            r[k].data = NULL;
            memset(&r[k].view, 0, sizeof(Py_buffer));
            got++;
            continue;
        }
        if (get_rows(args[at[k]], &r[k], at[k] >= 9) < 0) goto done;
        got++;
    }
    if (pairs) {
        if (get_indices(args[1], &ib) < 0) goto done;
        got_i = 1;
        if (get_indices(args[2], &jb) < 0) goto done;
        got_j = 1;
        if (ib.len != jb.len) {
            PyErr_SetString(PyExc_ValueError, "buffer_period: shapes differ");
            goto done;
        }
    }
    if (get_bytes(args[6], &cb, 0) < 0) goto done;
    got_c = 1;
    if (get_bytes(args[12], &fb, 1) < 0) goto done;
    got_f = 1;
    Rows *pos = &r[0], *v1 = &r[1], *v2 = &r[2], *vel = &r[3], *theta = &r[4];
    Rows *d2 = &r[5], *v = &r[6], *vel_out = &r[7], *cmd = &r[8];
    Py_ssize_t N = v1->len;
    Py_ssize_t P = pairs ? ib.len : 0;
    if (pos->len != 2 * N || v2->len != N || vel->len != 2 * N || theta->len != N ||
        v->len != 2 * N || vel_out->len != 2 * N || cmd->len != 2 * N ||
        cb.len != N || cb.itemsize != 1 || fb.len != N || fb.itemsize != 1 ||
        (pairs && (P == 0 || d2->len % P != 0)) || (known && given.len != d2->len)) {
        PyErr_SetString(PyExc_ValueError, "buffer_period: shapes differ");
        goto done;
    }
    if (known) {
        memcpy(d2->data, given.data, (size_t)d2->len * sizeof(double));
    }
    if (pairs) {
        const Py_ssize_t *ii = ib.data, *jj = jb.data;
        Py_ssize_t K = d2->len / P, n = K ? N / K : 0;
        if (K * n != N) {
            PyErr_SetString(PyExc_ValueError, "buffer_period: shapes differ");
            goto done;
        }
        for (Py_ssize_t q = 0; q < P; q++) {
            if (ii[q] < 0 || ii[q] >= n || jj[q] < 0 || jj[q] >= n) {
                PyErr_SetString(PyExc_IndexError, "buffer_period: a pair out of range");
                goto done;
            }
        }
        const double *p = pos->data;
        for (Py_ssize_t w = 0; w < K; w++) {
            const double *pw = p + 2 * n * w;
            double *out = d2->data + P * w;
            for (Py_ssize_t q = 0; q < P; q++) {
                double x = pw[2 * ii[q]] - pw[2 * jj[q]];
                double y = pw[2 * ii[q] + 1] - pw[2 * jj[q] + 1];
                out[q] = x * x + y * y;
            }
        }
    }
    const unsigned char *contact = cb.buf;
    unsigned char *free_ = fb.buf;
    for (Py_ssize_t k = 0; k < N; k++) {
        double a = v1->data[k], b = v2->data[k];
        v->data[k] = a;
        v->data[N + k] = b;
        vel_out->data[2 * k] = vel->data[2 * k];
        vel_out->data[2 * k + 1] = vel->data[2 * k + 1];
        free_[k] = !contact[k];
        double heading = theta->data[k] + 0.5 * b * h;
        cmd->data[2 * k] = a * cos(heading);
        cmd->data[2 * k + 1] = a * sin(heading);
    }
    result = Py_None;
    Py_INCREF(result);
done:
    for (int k = 0; k < got; k++) {
        if (r[k].view.obj != NULL) {
            PyBuffer_Release(&r[k].view);
        }
    }
    if (got_i) PyBuffer_Release(&ib.view);
    if (got_j) PyBuffer_Release(&jb.view);
    if (got_c) PyBuffer_Release(&cb);
    if (got_f) PyBuffer_Release(&fb);
    PyBuffer_Release(&given.view); /* nothing where not acquired (obj NULL) */
    return result;
}

PyDoc_STRVAR(flush_periods_doc,
"flush_periods(m, K, n, rel_tol, abs_tol, has_prev, has_cmd, d2, v, vel, cmd,\n"
"              free, best, effort_v1, effort_v2, peak_v1, prev, commanded,\n"
"              was_free, max_velocity_error, max_speed_error, free_periods,\n"
"              saturated_periods) -> None\n"
"\n"
"LoopTally.flush of ``m`` buffered periods of K worlds of n vehicles (N = K n):\n"
"``d2`` (m, K, P) (P = 0: no pairs), ``v`` (m, 2, N), ``vel``, ``cmd`` (m, N, 2),\n"
"``free`` (m, N) bool; updates ``best`` (K,), the efforts and ``peak_v1`` (N,),\n"
"``prev`` (2, N), ``commanded`` (N, 2) and ``was_free`` (N,) (the last period's,\n"
"read where ``has_prev``, ``has_cmd``), the errors (K,) and the counts (K,)\n"
"int64.");

static PyObject *
flush_periods(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 23) {
        PyErr_SetString(PyExc_TypeError, "flush_periods takes 23 arguments");
        return NULL;
    }
    Py_ssize_t m = PyLong_AsSsize_t(args[0]);
    Py_ssize_t K = PyLong_AsSsize_t(args[1]);
    Py_ssize_t n = PyLong_AsSsize_t(args[2]);
    double rel_tol = PyFloat_AsDouble(args[3]);
    double abs_tol = PyFloat_AsDouble(args[4]);
    int has_prev = PyObject_IsTrue(args[5]);
    int has_cmd = PyObject_IsTrue(args[6]);
    if (PyErr_Occurred() || has_prev < 0 || has_cmd < 0) {
        return NULL;
    }
    /* float64: d2, v, vel, cmd, best, effort_v1, effort_v2, peak_v1, prev,
       commanded, max_velocity_error, max_speed_error */
    static const int at[] = {7, 8, 9, 10, 12, 13, 14, 15, 16, 17, 19, 20};
    Rows r[12];
    Py_buffer fb, wb, cb_free, cb_sat;
    int got = 0, got_f = 0, got_w = 0, got_cf = 0, got_cs = 0;
    PyObject *result = NULL;
    for (int k = 0; k < 12; k++) {
        if (get_rows(args[at[k]], &r[k], at[k] >= 12) < 0) goto done;
        got++;
    }
    if (get_bytes(args[11], &fb, 0) < 0) goto done;
    got_f = 1;
    if (get_bytes(args[18], &wb, 1) < 0) goto done;
    got_w = 1;
    /* the counts: int64 (numpy's default integer here, checked by the caller) */
    if (PyObject_GetBuffer(args[21], &cb_free, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE) < 0)
        goto done;
    got_cf = 1;
    if (PyObject_GetBuffer(args[22], &cb_sat, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE) < 0)
        goto done;
    got_cs = 1;
    Py_ssize_t N = K * n;
    Rows *d2 = &r[0], *v = &r[1], *vel = &r[2], *cmd = &r[3], *best = &r[4];
    Rows *e1 = &r[5], *e2 = &r[6], *peak = &r[7], *prev = &r[8], *commanded = &r[9];
    Rows *mve = &r[10], *mse = &r[11];
    Py_ssize_t P = K > 0 && m > 0 ? d2->len / (m * K) : 0;
    if (m < 1 || K < 1 || n < 1 || d2->len != m * K * P || v->len != m * 2 * N ||
        vel->len != m * 2 * N || cmd->len != m * 2 * N || fb.len != m * N ||
        fb.itemsize != 1 || best->len != K || e1->len != N || e2->len != N ||
        peak->len != N || prev->len != 2 * N || commanded->len != 2 * N ||
        wb.len != N || wb.itemsize != 1 || mve->len != K || mse->len != K ||
        cb_free.len != K * 8 || cb_free.itemsize != 8 || cb_sat.len != K * 8 ||
        cb_sat.itemsize != 8) {
        PyErr_SetString(PyExc_ValueError, "flush_periods: shapes differ");
        goto done;
    }
    const unsigned char *free_ = fb.buf;
    unsigned char *was_free = wb.buf;
    long long *free_periods = cb_free.buf, *saturated = cb_sat.buf;
    /* closest approach: each period's least squared distance of each world, its
       root, the least over the periods, then against the best so far */
    if (P > 0) {
        for (Py_ssize_t w = 0; w < K; w++) {
            double least = 0.0;
            for (Py_ssize_t t = 0; t < m; t++) {
                const double *row = d2->data + (t * K + w) * P;
                double low = row[0];
                for (Py_ssize_t c = 1; c < P; c++) {
                    low = smaller(low, row[c]);
                }
                low = sqrt(low);
                least = t == 0 ? low : smaller(least, low);
            }
            best->data[w] = smaller(best->data[w], least);
        }
    }
    /* control effort, period after period as the loop adds them, and |v1|'s peak */
    const double *v0 = v->data;
    if (!has_prev) {
        memcpy(prev->data, v0, 2 * N * sizeof(double));
    }
    for (Py_ssize_t t = has_prev ? 0 : 1; t < m; t++) {
        const double *now = v->data + t * 2 * N;
        const double *before = t == 0 ? prev->data : now - 2 * N;
        for (Py_ssize_t i = 0; i < N; i++) {
            e1->data[i] = e1->data[i] + fabs(now[i] - before[i]);
            e2->data[i] = e2->data[i] + fabs(now[N + i] - before[N + i]);
        }
    }
    for (Py_ssize_t i = 0; i < N; i++) {
        /* the largest, NaN left out (fmax) */
        double top = fabs(v0[i]);
        for (Py_ssize_t t = 1; t < m; t++) {
            top = fmax(top, fabs(v->data[t * 2 * N + i]));
        }
        peak->data[i] = fmax(peak->data[i], top);
    }
    memcpy(prev->data, v->data + (m - 1) * 2 * N, 2 * N * sizeof(double));
    /* the motor check: each period's velocities read against the last commanded */
    for (Py_ssize_t w = 0; w < K; w++) {
        double worst_v = -INFINITY, worst_s = -INFINITY;
        long long checked = 0, over = 0;
        for (Py_ssize_t t = has_cmd ? 0 : 1; t < m; t++) {
            const double *c_at = t == 0 ? commanded->data : cmd->data + (t - 1) * 2 * N;
            const unsigned char *f_at = t == 0 ? was_free : free_ + (t - 1) * N;
            for (Py_ssize_t j = 0; j < n; j++) {
                Py_ssize_t i = w * n + j;
                const double *got_v = vel->data + (t * N + i) * 2, *c = c_at + 2 * i;
                if (!(free_[t * N + i] && f_at[i] && isfinite(got_v[0]) &&
                      isfinite(got_v[1]))) {
                    continue;
                }
                double want = hypot(c[0], c[1]);
                double err = hypot(got_v[0] - c[0], got_v[1] - c[1]);
                double speed_err = fabs(hypot(got_v[0], got_v[1]) - want);
                worst_v = larger(worst_v, err);
                worst_s = larger(worst_s, speed_err);
                checked++;
                over += err > larger(rel_tol * want, abs_tol);
            }
        }
        mve->data[w] = larger(mve->data[w], worst_v);
        mse->data[w] = larger(mse->data[w], worst_s);
        free_periods[w] += checked;
        saturated[w] += over;
    }
    memcpy(commanded->data, cmd->data + (m - 1) * 2 * N, 2 * N * sizeof(double));
    memcpy(was_free, free_ + (m - 1) * N, (size_t)N);
    result = Py_None;
    Py_INCREF(result);
done:
    release(r, got);
    if (got_f) PyBuffer_Release(&fb);
    if (got_w) PyBuffer_Release(&wb);
    if (got_cf) PyBuffer_Release(&cb_free);
    if (got_cs) PyBuffer_Release(&cb_sat);
    return result;
}

PyDoc_STRVAR(read_state_doc,
"read_state(rows, measured, pos, theta, vel) -> (pos, theta, vel)\n"
"\n"
"The bodies' rows (N, 6) as read, (x1, x2, x3, v_x1, v_x2, omega), split (copies):\n"
"``measured`` (N, 3) the velocities, ``pos`` (N, 2), ``theta`` (N,), ``vel``\n"
"(N, 2). ``pos``, ``theta``, ``vel`` None: new arrays (where the module's\n"
"ALLOCATES), all three or none.");

static PyObject *
read_state(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "read_state takes 5 arguments");
        return NULL;
    }
    PyObject *out[3] = {NULL, NULL, NULL}, *result = NULL;
    Rows r[5];
    int got = 0;
    for (int k = 0; k < 2; k++) { /* rows, measured */
        if (get_rows(args[k], &r[k], k == 1) < 0) goto done;
        got++;
    }
    int given = args[2] != Py_None, none = args[2] == Py_None;
    for (int k = 3; k < 5; k++) {
        given &= args[k] != Py_None;
        none &= args[k] == Py_None;
    }
    if (given) {
        for (int k = 0; k < 3; k++) {
            out[k] = args[2 + k];
            Py_INCREF(out[k]);
        }
    }
    else if (none) { /* as many rows as ``measured`` */
        Py_ssize_t n = r[1].len / 3;
        out[0] = new_array(2, n, 2, 0);
        out[1] = new_array(1, n, 0, 0);
        out[2] = new_array(2, n, 2, 0);
        if (out[0] == NULL || out[1] == NULL || out[2] == NULL) goto done;
    }
    else {
        PyErr_SetString(PyExc_TypeError, "read_state: all three outputs or none");
        goto done;
    }
    for (int k = 2; k < 5; k++) {
        if (get_rows(out[k - 2], &r[k], 1) < 0) goto done;
        got++;
    }
    Py_ssize_t N = r[3].len;
    if (r[0].len != 6 * N || r[1].len != 3 * N || r[2].len != 2 * N ||
        r[4].len != 2 * N) {
        PyErr_SetString(PyExc_ValueError, "read_state: shapes differ");
        goto done;
    }
    const double *rows = r[0].data;
    double *measured = r[1].data, *pos = r[2].data, *theta = r[3].data;
    double *vel = r[4].data;
    for (Py_ssize_t i = 0; i < N; i++) {
        const double *row = rows + 6 * i;
        pos[2 * i] = row[0];
        pos[2 * i + 1] = row[1];
        theta[i] = row[2];
        vel[2 * i] = row[3];
        vel[2 * i + 1] = row[4];
        measured[3 * i] = row[3];
        measured[3 * i + 1] = row[4];
        measured[3 * i + 2] = row[5];
    }
    result = PyTuple_Pack(3, out[0], out[1], out[2]);
done:
    release(r, got);
    for (int k = 0; k < 3; k++) {
        Py_XDECREF(out[k]);
    }
    return result;
}

PyDoc_STRVAR(command_rows_doc,
"command_rows(commanded, v2, out) -> None\n"
"\n"
"The motors' commands of N vehicles: ``out`` (N, 3) takes ``commanded`` (N, 2), the\n"
"velocities along the mean heading, in its first two columns and ``v2`` (N,) in\n"
"its third (``out[:, :2] = commanded; out[:, 2] = v2``).");

static PyObject *
command_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "command_rows takes 3 arguments");
        return NULL;
    }
    Rows r[3];
    if (get_all_rows(args, r, 3, 2) < 0) {
        return NULL;
    }
    int got = 3;
    Py_ssize_t N = r[1].len;
    if (r[0].len != 2 * N || r[2].len != 3 * N) {
        release(r, got);
        PyErr_SetString(PyExc_ValueError, "command_rows: shapes differ");
        return NULL;
    }
    const double *cmd = r[0].data, *v2 = r[1].data;
    double *out = r[2].data;
    for (Py_ssize_t i = 0; i < N; i++) {
        out[3 * i] = cmd[2 * i];
        out[3 * i + 1] = cmd[2 * i + 1];
        out[3 * i + 2] = v2[i];
    }
    release(r, got);
    Py_RETURN_NONE;
}

PyDoc_STRVAR(record_sample_doc,
"record_sample(c, pos, theta, v1, v2, chi, slot, target, mode, failed, pose_out,\n"
"              cmd_out, chi_out, slot_out, target_out, mode_out, failed_out) -> None\n"
"\n"
"Sample ``c`` of every world into the record's buffers (a copy): ``pos``, ``chi``,\n"
"``slot``, ``target`` (N, 2), ``theta``, ``v1``, ``v2`` (N,) float64, ``mode`` (N,)\n"
"int8 and ``failed`` (N,) bool into ``pose_out`` (T, N, 3) as (x, y, theta),\n"
"``cmd_out`` (T, N, 2) as (v1, v2), ``chi_out``, ``slot_out``, ``target_out``\n"
"(T, N, 2), ``mode_out`` and ``failed_out`` (T, N), at row ``c``.");

static PyObject *
record_sample(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 17) {
        PyErr_SetString(PyExc_TypeError, "record_sample takes 17 arguments");
        return NULL;
    }
    Py_ssize_t c = PyLong_AsSsize_t(args[0]);
    if (c == -1 && PyErr_Occurred()) {
        return NULL;
    }
    /* float64: pos, theta, v1, v2, chi, slot, target, then the five buffers */
    static const int at[] = {1, 2, 3, 4, 5, 6, 7, 10, 11, 12, 13, 14};
    Rows r[12];
    Py_buffer b[4]; /* mode, failed, mode_out, failed_out */
    static const int bytes_at[] = {8, 9, 15, 16};
    int got = 0, got_b = 0;
    PyObject *result = NULL;
    for (int k = 0; k < 12; k++) {
        if (get_rows(args[at[k]], &r[k], at[k] >= 10) < 0) goto done;
        got++;
    }
    for (int k = 0; k < 4; k++) {
        if (get_bytes(args[bytes_at[k]], &b[k], bytes_at[k] >= 15) < 0) goto done;
        got_b++;
    }
    Rows *pos = &r[0], *theta = &r[1], *v1 = &r[2], *v2 = &r[3], *chi = &r[4];
    Rows *slot = &r[5], *target = &r[6];
    Py_ssize_t N = theta->len;
    int fits = pos->len == 2 * N && v1->len == N && v2->len == N &&
               chi->len == 2 * N && slot->len == 2 * N && target->len == 2 * N &&
               b[0].len == N && b[1].len == N && b[0].itemsize == 1 &&
               b[1].itemsize == 1 && b[2].itemsize == 1 && b[3].itemsize == 1 &&
               c >= 0 && (c + 1) * 3 * N <= r[7].len && (c + 1) * 2 * N <= r[8].len &&
               (c + 1) * 2 * N <= r[9].len && (c + 1) * 2 * N <= r[10].len &&
               (c + 1) * 2 * N <= r[11].len && (c + 1) * N <= b[2].len &&
               (c + 1) * N <= b[3].len;
    if (!fits) {
        PyErr_SetString(PyExc_ValueError, "record_sample: shapes differ");
        goto done;
    }
    double *pose = r[7].data + c * 3 * N, *cmd = r[8].data + c * 2 * N;
    for (Py_ssize_t k = 0; k < N; k++) {
        pose[3 * k] = pos->data[2 * k];
        pose[3 * k + 1] = pos->data[2 * k + 1];
        pose[3 * k + 2] = theta->data[k];
        cmd[2 * k] = v1->data[k];
        cmd[2 * k + 1] = v2->data[k];
    }
    memcpy(r[9].data + c * 2 * N, chi->data, 2 * N * sizeof(double));
    memcpy(r[10].data + c * 2 * N, slot->data, 2 * N * sizeof(double));
    memcpy(r[11].data + c * 2 * N, target->data, 2 * N * sizeof(double));
    memcpy((char *)b[2].buf + c * N, b[0].buf, (size_t)N);
    memcpy((char *)b[3].buf + c * N, b[1].buf, (size_t)N);
    result = Py_None;
    Py_INCREF(result);
done:
    release(r, got);
    for (int k = 0; k < got_b; k++) {
        PyBuffer_Release(&b[k]);
    }
    return result;
}

static PyMethodDef methods[] = {
    {"healthy", (PyCFunction)(void (*)(void))healthy, METH_FASTCALL, healthy_doc},
    {"buffer_period", (PyCFunction)(void (*)(void))buffer_period, METH_FASTCALL,
     buffer_period_doc},
    {"record_sample", (PyCFunction)(void (*)(void))record_sample, METH_FASTCALL,
     record_sample_doc},
    {"flush_periods", (PyCFunction)(void (*)(void))flush_periods, METH_FASTCALL,
     flush_periods_doc},
    {"read_state", (PyCFunction)(void (*)(void))read_state, METH_FASTCALL,
     read_state_doc},
    {"command_rows", (PyCFunction)(void (*)(void))command_rows, METH_FASTCALL,
     command_rows_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_period",
    "Pieces of the loop's period in C (see sandbox/loop/divergence.py, tally.py, "
    "recording.py, stepping.py).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__period(void)
{
    return module_allocating(&module);
}
