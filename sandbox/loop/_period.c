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
 * (sandbox/loop/recording.py, LoopRecord.append): copies only.
 *
 * read_state: the bodies' rows split into positions, headings, velocities and the
 * motors' measured velocities (sandbox/loop/stepping.py, LoopPhysics.read):
 * copies only.
 *
 * command_rows: the motors' commands of a period from the loop metrics' velocities
 * along the mean heading (LoopPhysics.advance): copies only.
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

/* The arguments of buffer_period, by name (accel.h). */
#define BUFFER_PERIOD(X)                                                           \
    X(pos, FLOATS, 0)                                                              \
    X(i, INTPS, OR_NONE)                                                           \
    X(j, INTPS, OR_NONE)                                                           \
    X(v1, FLOATS, 0)                                                               \
    X(v2, FLOATS, 0)                                                               \
    X(vel, FLOATS, 0)                                                              \
    X(contact, BYTES, 0)                                                           \
    X(theta, FLOATS, 0)                                                            \
    X(h, NUMBER, 0)                                                                \
    X(d2, FLOATS, WRITTEN | OR_NONE)                                               \
    X(v, FLOATS, WRITTEN)                                                          \
    X(vel_out, FLOATS, WRITTEN)                                                    \
    X(free, BYTES, WRITTEN)                                                        \
    X(cmd, FLOATS, WRITTEN)                                                        \
    X(d2_known, FLOATS, OR_NONE)
NAMED(buffer_period, BUFFER_PERIOD)

PyDoc_STRVAR(buffer_period_doc,
"buffer_period(*, pos, i, j, v1, v2, vel, contact, theta, h, d2, v, vel_out, free,\n"
"              cmd, d2_known) -> None\n"
"\n"
"For N vehicles: ``pos``, ``vel`` (N, 2), ``v1``, ``v2``, ``theta`` (N,), ``contact``\n"
"(N,) bool, the pairs ``i``, ``j`` (intp, each world's rows from 0, P of them) or\n"
"None; writes ``d2`` (K, P) (where ``i`` is given), ``v`` (2, N), ``vel_out``\n"
"(N, 2), ``free`` (N,) bool and ``cmd`` (N, 2), ``v1 (cos, sin)(theta + v2 h / 2)``;\n"
"without pairs, ``d2_known`` (K P) if given is copied into ``d2``.");

static PyObject *
buffer_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
              PyObject *kwnames)
{
    buffer_period_args a;
    if (parse_named(&buffer_period_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    const double h = a.h.x;
    const int pairs = a.i.i != NULL, known = !pairs && a.d2_known.f != NULL;
    const Arg *pos = &a.pos, *v1 = &a.v1, *v2 = &a.v2, *vel = &a.vel;
    const Arg *theta = &a.theta, *d2 = &a.d2, *v = &a.v, *vel_out = &a.vel_out;
    const Arg *cmd = &a.cmd, *given = &a.d2_known;
    const Py_ssize_t N = v1->len, P = pairs ? a.i.len : 0;
    if (pos->len != 2 * N || v2->len != N || vel->len != 2 * N || theta->len != N ||
        v->len != 2 * N || vel_out->len != 2 * N || cmd->len != 2 * N ||
        a.contact.len != N || a.free.len != N || (pairs && a.j.len != P) ||
        ((pairs || known) && d2->f == NULL) || (pairs && (P == 0 || d2->len % P != 0)) ||
        (known && given->len != d2->len)) {
        PyErr_SetString(PyExc_ValueError, "buffer_period: shapes differ");
        goto done;
    }
    if (known) {
        memcpy(d2->f, given->f, (size_t)d2->len * sizeof(double));
    }
    if (pairs) {
        const Py_ssize_t *ii = a.i.i, *jj = a.j.i;
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
        const double *p = pos->f;
        for (Py_ssize_t w = 0; w < K; w++) {
            const double *pw = p + 2 * n * w;
            double *out = d2->f + P * w;
            for (Py_ssize_t q = 0; q < P; q++) {
                double x = pw[2 * ii[q]] - pw[2 * jj[q]];
                double y = pw[2 * ii[q] + 1] - pw[2 * jj[q] + 1];
                out[q] = x * x + y * y;
            }
        }
    }
    const unsigned char *contact = a.contact.b;
    unsigned char *free_ = a.free.b;
    for (Py_ssize_t k = 0; k < N; k++) {
        double speed = v1->f[k], turn = v2->f[k];
        v->f[k] = speed;
        v->f[N + k] = turn;
        vel_out->f[2 * k] = vel->f[2 * k];
        vel_out->f[2 * k + 1] = vel->f[2 * k + 1];
        free_[k] = !contact[k];
        double heading = theta->f[k] + 0.5 * turn * h;
        cmd->f[2 * k] = speed * cos(heading);
        cmd->f[2 * k + 1] = speed * sin(heading);
    }
    result = Py_None;
    Py_INCREF(result);
done:
    release_named(&buffer_period_signature, (Arg *)&a);
    return result;
}

/* The arguments of flush_periods, by name (accel.h). */
#define FLUSH_PERIODS(X)                                                           \
    X(m, INTEGER, 0)                                                               \
    X(K, INTEGER, 0)                                                               \
    X(n, INTEGER, 0)                                                               \
    X(rel_tol, NUMBER, 0)                                                          \
    X(abs_tol, NUMBER, 0)                                                          \
    X(has_prev, INTEGER, 0)                                                        \
    X(has_cmd, INTEGER, 0)                                                         \
    X(d2, FLOATS, 0)                                                               \
    X(v, FLOATS, 0)                                                                \
    X(vel, FLOATS, 0)                                                              \
    X(cmd, FLOATS, 0)                                                              \
    X(free, BYTES, 0)                                                              \
    X(best, FLOATS, WRITTEN)                                                       \
    X(effort_v1, FLOATS, WRITTEN)                                                  \
    X(effort_v2, FLOATS, WRITTEN)                                                  \
    X(peak_v1, FLOATS, WRITTEN)                                                    \
    X(prev, FLOATS, WRITTEN)                                                       \
    X(commanded, FLOATS, WRITTEN)                                                  \
    X(was_free, BYTES, WRITTEN)                                                    \
    X(max_velocity_error, FLOATS, WRITTEN)                                         \
    X(max_speed_error, FLOATS, WRITTEN)                                            \
    X(free_periods, INT64S, WRITTEN)                                               \
    X(saturated_periods, INT64S, WRITTEN)
NAMED(flush_periods, FLUSH_PERIODS)

PyDoc_STRVAR(flush_periods_doc,
"flush_periods(*, m, K, n, rel_tol, abs_tol, has_prev, has_cmd, d2, v, vel, cmd,\n"
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
flush_periods(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
              PyObject *kwnames)
{
    flush_periods_args a;
    if (parse_named(&flush_periods_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    const Py_ssize_t m = a.m.n, K = a.K.n, n = a.n.n, N = K * n;
    const double rel_tol = a.rel_tol.x, abs_tol = a.abs_tol.x;
    const int has_prev = a.has_prev.n != 0, has_cmd = a.has_cmd.n != 0;
    const Arg *d2 = &a.d2, *v = &a.v, *vel = &a.vel, *cmd = &a.cmd, *best = &a.best;
    const Arg *e1 = &a.effort_v1, *e2 = &a.effort_v2, *peak = &a.peak_v1;
    const Arg *prev = &a.prev, *commanded = &a.commanded;
    const Arg *mve = &a.max_velocity_error, *mse = &a.max_speed_error;
    Py_ssize_t P = K > 0 && m > 0 ? d2->len / (m * K) : 0;
    if (m < 1 || K < 1 || n < 1 || d2->len != m * K * P || v->len != m * 2 * N ||
        vel->len != m * 2 * N || cmd->len != m * 2 * N || a.free.len != m * N ||
        best->len != K || e1->len != N || e2->len != N || peak->len != N ||
        prev->len != 2 * N || commanded->len != 2 * N || a.was_free.len != N ||
        mve->len != K || mse->len != K || a.free_periods.len != K ||
        a.saturated_periods.len != K) {
        PyErr_SetString(PyExc_ValueError, "flush_periods: shapes differ");
        goto done;
    }
    const unsigned char *free_ = a.free.b;
    unsigned char *was_free = a.was_free.b;
    int64_t *free_periods = a.free_periods.q, *saturated = a.saturated_periods.q;
    /* closest approach: each period's least squared distance of each world, its
       root, the least over the periods, then against the best so far */
    if (P > 0) {
        for (Py_ssize_t w = 0; w < K; w++) {
            double least = 0.0;
            for (Py_ssize_t t = 0; t < m; t++) {
                const double *row = d2->f + (t * K + w) * P;
                double low = row[0];
                for (Py_ssize_t c = 1; c < P; c++) {
                    low = smaller(low, row[c]);
                }
                low = sqrt(low);
                least = t == 0 ? low : smaller(least, low);
            }
            best->f[w] = smaller(best->f[w], least);
        }
    }
    /* control effort, period after period as the loop adds them, and |v1|'s peak */
    const double *v0 = v->f;
    if (!has_prev) {
        memcpy(prev->f, v0, 2 * N * sizeof(double));
    }
    for (Py_ssize_t t = has_prev ? 0 : 1; t < m; t++) {
        const double *now = v->f + t * 2 * N;
        const double *before = t == 0 ? prev->f : now - 2 * N;
        for (Py_ssize_t i = 0; i < N; i++) {
            e1->f[i] = e1->f[i] + fabs(now[i] - before[i]);
            e2->f[i] = e2->f[i] + fabs(now[N + i] - before[N + i]);
        }
    }
    for (Py_ssize_t i = 0; i < N; i++) {
        /* the largest, NaN left out (fmax) */
        double top = fabs(v0[i]);
        for (Py_ssize_t t = 1; t < m; t++) {
            top = fmax(top, fabs(v->f[t * 2 * N + i]));
        }
        peak->f[i] = fmax(peak->f[i], top);
    }
    memcpy(prev->f, v->f + (m - 1) * 2 * N, 2 * N * sizeof(double));
    /* the motor check: each period's velocities read against the last commanded */
    for (Py_ssize_t w = 0; w < K; w++) {
        double worst_v = -INFINITY, worst_s = -INFINITY;
        long long checked = 0, over = 0;
        for (Py_ssize_t t = has_cmd ? 0 : 1; t < m; t++) {
            const double *c_at = t == 0 ? commanded->f : cmd->f + (t - 1) * 2 * N;
            const unsigned char *f_at = t == 0 ? was_free : free_ + (t - 1) * N;
            for (Py_ssize_t j = 0; j < n; j++) {
                Py_ssize_t i = w * n + j;
                const double *got_v = vel->f + (t * N + i) * 2, *c = c_at + 2 * i;
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
        mve->f[w] = larger(mve->f[w], worst_v);
        mse->f[w] = larger(mse->f[w], worst_s);
        free_periods[w] += checked;
        saturated[w] += over;
    }
    memcpy(commanded->f, cmd->f + (m - 1) * 2 * N, 2 * N * sizeof(double));
    memcpy(was_free, free_ + (m - 1) * N, (size_t)N);
    result = Py_None;
    Py_INCREF(result);
done:
    release_named(&flush_periods_signature, (Arg *)&a);
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

/* The arguments of record_sample, by name (accel.h). */
#define RECORD_SAMPLE(X)                                                           \
    X(c, INTEGER, 0)                                                               \
    X(pos, FLOATS, 0)                                                              \
    X(theta, FLOATS, 0)                                                            \
    X(v1, FLOATS, 0)                                                               \
    X(v2, FLOATS, 0)                                                               \
    X(chi, FLOATS, 0)                                                              \
    X(slot, FLOATS, 0)                                                             \
    X(target, FLOATS, 0)                                                           \
    X(mode, BYTES, 0)                                                              \
    X(failed, BYTES, 0)                                                            \
    X(pose_out, FLOATS, WRITTEN)                                                   \
    X(cmd_out, FLOATS, WRITTEN)                                                    \
    X(chi_out, FLOATS, WRITTEN)                                                    \
    X(slot_out, FLOATS, WRITTEN)                                                   \
    X(target_out, FLOATS, WRITTEN)                                                 \
    X(mode_out, BYTES, WRITTEN)                                                    \
    X(failed_out, BYTES, WRITTEN)
NAMED(record_sample, RECORD_SAMPLE)

PyDoc_STRVAR(record_sample_doc,
"record_sample(*, c, pos, theta, v1, v2, chi, slot, target, mode, failed, pose_out,\n"
"              cmd_out, chi_out, slot_out, target_out, mode_out, failed_out)\n"
"    -> None\n"
"\n"
"Sample ``c`` of every world into the record's buffers (a copy): ``pos``, ``chi``,\n"
"``slot``, ``target`` (N, 2), ``theta``, ``v1``, ``v2`` (N,) float64, ``mode`` (N,)\n"
"int8 and ``failed`` (N,) bool into ``pose_out`` (T, N, 3) as (x, y, theta),\n"
"``cmd_out`` (T, N, 2) as (v1, v2), ``chi_out``, ``slot_out``, ``target_out``\n"
"(T, N, 2), ``mode_out`` and ``failed_out`` (T, N), at row ``c``.");

static PyObject *
record_sample(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
              PyObject *kwnames)
{
    record_sample_args a;
    if (parse_named(&record_sample_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    const Py_ssize_t c = a.c.n, N = a.theta.len;
    int fits = a.pos.len == 2 * N && a.v1.len == N && a.v2.len == N &&
               a.chi.len == 2 * N && a.slot.len == 2 * N && a.target.len == 2 * N &&
               a.mode.len == N && a.failed.len == N && c >= 0 &&
               (c + 1) * 3 * N <= a.pose_out.len && (c + 1) * 2 * N <= a.cmd_out.len &&
               (c + 1) * 2 * N <= a.chi_out.len && (c + 1) * 2 * N <= a.slot_out.len &&
               (c + 1) * 2 * N <= a.target_out.len && (c + 1) * N <= a.mode_out.len &&
               (c + 1) * N <= a.failed_out.len;
    if (!fits) {
        PyErr_SetString(PyExc_ValueError, "record_sample: shapes differ");
        goto done;
    }
    const double *pos = a.pos.f, *theta = a.theta.f, *v1 = a.v1.f, *v2 = a.v2.f;
    double *pose = a.pose_out.f + c * 3 * N, *cmd = a.cmd_out.f + c * 2 * N;
    for (Py_ssize_t k = 0; k < N; k++) {
        pose[3 * k] = pos[2 * k];
        pose[3 * k + 1] = pos[2 * k + 1];
        pose[3 * k + 2] = theta[k];
        cmd[2 * k] = v1[k];
        cmd[2 * k + 1] = v2[k];
    }
    memcpy(a.chi_out.f + c * 2 * N, a.chi.f, 2 * N * sizeof(double));
    memcpy(a.slot_out.f + c * 2 * N, a.slot.f, 2 * N * sizeof(double));
    memcpy(a.target_out.f + c * 2 * N, a.target.f, 2 * N * sizeof(double));
    memcpy(a.mode_out.b + c * N, a.mode.b, (size_t)N);
    memcpy(a.failed_out.b + c * N, a.failed.b, (size_t)N);
    result = Py_None;
    Py_INCREF(result);
done:
    release_named(&record_sample_signature, (Arg *)&a);
    return result;
}

static PyMethodDef methods[] = {
    {"healthy", (PyCFunction)(void (*)(void))healthy, METH_FASTCALL, healthy_doc},
    {"buffer_period", (PyCFunction)(void (*)(void))buffer_period,
     METH_FASTCALL | METH_KEYWORDS, buffer_period_doc},
    {"record_sample", (PyCFunction)(void (*)(void))record_sample,
     METH_FASTCALL | METH_KEYWORDS, record_sample_doc},
    {"flush_periods", (PyCFunction)(void (*)(void))flush_periods,
     METH_FASTCALL | METH_KEYWORDS, flush_periods_doc},
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
