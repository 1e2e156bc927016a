/* The residual detector's pass of one control period, every vehicle in one C call.
 *
 * sandbox/behaviour/residual_kernel.py calls this where this optional extension is
 * built (the compiled path ``residual`` of sandbox/accel.py). Row by row (every vehicle of every world;
 * the rows never mix), it does what sandbox/behaviour/detection.py's residual does
 * to the DetectorState between the history's append and the reading of a kind: the
 * motor model (_advance_model, motor_model.h), the age of the window and its
 * restart at a fresh observation, the contact gate, and for a due window the
 * residual in the predicted frame, its normalisation, the log-likelihood ratio
 * (llr), the clearing CUSUM of a detected vehicle and the CUSUM g of the others,
 * the sums for isolation (_accumulate), and an alarm's latch and the end of its
 * isolation. It lists the rows whose kind Python reads next (_isolate): those read
 * on while isolating, the cleared ones and the alarms.
 *
 * sqrt, hypot, sin, cos, exp, log and log1p are the C library's; the numbers agree
 * with the numpy path within the tolerance of sandbox/accel.py.
 */

#include "accel.h"
#include "motor_model.h"

/* detection.llr of one |z| for the shift mu, and mu^2 / 2 as Python takes it. */
static inline double
llr(double z_norm, double mu, double half_mu2)
{
    double x = mu * z_norm;
    double value;
    if (x < 1e-4) {
        value = x * x / 6.0;
    }
    else { /* log(sinh(x) / x) */
        value = x + log1p(-exp(-2.0 * x)) - log(2.0 * x);
    }
    return value - half_mu2;
}

/* detection._floored: x where x > 0, else 0.0. */
static inline double
floored(double x)
{
    return x > 0.0 ? x : 0.0;
}

/* The DetectorState's fields, read by name from the state (accel.h). */
#define DETECTOR_STATE(X)                                                          \
    X(pose, FLOATS, WRITTEN)                                                       \
    X(start, FLOATS, WRITTEN)                                                      \
    X(vel, FLOATS, WRITTEN)                                                        \
    X(rate, FLOATS, WRITTEN)                                                       \
    X(travel, FLOATS, WRITTEN)                                                     \
    X(last_contact, FLOATS, WRITTEN)                                               \
    X(g, FLOATS, WRITTEN)                                                          \
    X(clear, FLOATS, WRITTEN)                                                      \
    X(acc, FLOATS, WRITTEN)                                                        \
    X(acc_abs, FLOATS, WRITTEN)                                                    \
    X(acc_raw, FLOATS, WRITTEN)                                                    \
    X(acc_obs, FLOATS, WRITTEN)                                                    \
    X(acc_pred, FLOATS, WRITTEN)                                                   \
    X(acc_t, FLOATS, WRITTEN)                                                      \
    X(acc_rot, FLOATS, WRITTEN)                                                    \
    X(acc_rot0, FLOATS, WRITTEN)                                                   \
    X(isolating, FLOATS, WRITTEN)                                                  \
    X(age, INT64S, WRITTEN)                                                        \
    X(gate, INT64S, WRITTEN)                                                       \
    X(acc_n, INT64S, WRITTEN)                                                      \
    X(pending, BYTES, WRITTEN)                                                     \
    X(detected, BYTES, WRITTEN)
NAMED(detector_state, DETECTOR_STATE)

/* The arguments of residual_period, by name (accel.h). */
#define RESIDUAL_PERIOD(X)                                                         \
    X(state, OBJECT, 0)                                                            \
    X(seen, FLOATS, 0)                                                             \
    X(fresh, BYTES, OR_NONE)                                                       \
    X(contact, BYTES, OR_NONE)                                                     \
    X(commands, FLOATS, 0)                                                         \
    X(motor_accel, FLOATS, 0)                                                      \
    X(turn_accel, FLOATS, 0)                                                       \
    X(brake, FLOATS, 0)                                                            \
    X(read, INT64S, WRITTEN)                                                       \
    X(cleared, INT64S, WRITTEN)                                                    \
    X(alarms, INT64S, WRITTEN)                                                     \
    X(trace_rows, INT64S, WRITTEN | OR_NONE)                                       \
    X(trace_inc, FLOATS, WRITTEN | OR_NONE)                                        \
    X(ring_values, FLOATS, WRITTEN | OR_NONE)                                      \
    X(ring_fresh, BYTES, WRITTEN | OR_NONE)                                        \
    X(slot, INTEGER, 0)                                                            \
    X(t, NUMBER, 0)                                                                \
    X(h, NUMBER, 0)                                                                \
    X(substeps, INTEGER, 0)                                                        \
    X(window, INTEGER, 0)                                                          \
    X(sp, NUMBER, 0)                                                               \
    X(sh, NUMBER, 0)                                                               \
    X(heading_noise, NUMBER, 0)                                                    \
    X(mu, NUMBER, 0)                                                               \
    X(lam, NUMBER, 0)                                                              \
    X(isolation, NUMBER, 0)                                                        \
    X(settle, NUMBER, 0)
NAMED(residual_period, RESIDUAL_PERIOD)

PyDoc_STRVAR(residual_period_doc,
"residual_period(*, state, seen, fresh, contact, commands, motor_accel, turn_accel,\n"
"                brake, read, cleared, alarms, trace_rows, trace_inc, ring_values,\n"
"                ring_fresh, slot, t, h, substeps, window, sp, sh, heading_noise,\n"
"                mu, lam, isolation, settle) -> (reads, clears, alarms, used)\n"
"\n"
"Stores the observed poses and fresh flags in row ``slot`` of the track\n"
"history's rings ``ring_values`` (L, n, 3) and ``ring_fresh`` (L, n) (None: no\n"
"history), then does one period of the residual detector for n rows: the arrays\n"
"of the DetectorState ``state`` (float64, the ages, gates and counts int64,\n"
"``pending`` and ``detected`` bool) advance in place from the observations\n"
"``seen`` (n, 3), ``fresh`` and ``contact`` (n,) bool or None (every row fresh,\n"
"none in contact), the commands (n, 2) and the drives' limits (n,). Writes the\n"
"rows read on while isolating, the cleared rows and the alarms to ``read``,\n"
"``cleared`` and ``alarms`` (int64, n), and where ``trace_rows`` is not None the\n"
"rows of every window used and their log-likelihood ratios to it and\n"
"``trace_inc`` (n); returns how many of each. ``window`` [periods], ``sp``, ``sh``\n"
"the residuals' standard deviations, ``mu`` the shift, ``lam`` the threshold,\n"
"``isolation`` [s] and ``settle`` [s], how long the track must show a braked\n"
"vehicle at rest.");

static PyObject *
residual_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
                PyObject *kwnames)
{
    residual_period_args a;
    detector_state_args st;
    if (parse_named(&residual_period_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    if (parse_attributes(&detector_state_signature, a.state.obj, (Arg *)&st) < 0) {
        release_named(&residual_period_signature, (Arg *)&a);
        return NULL;
    }
    PyObject *result = NULL;
    const long substeps = (long)a.substeps.n, window = (long)a.window.n;
    if (substeps < 1) {
        PyErr_SetString(PyExc_ValueError, "residual_period: bad substeps");
        goto done;
    }
    const Py_ssize_t n = st.rate.len;
    int shapes = st.pose.len == 3 * n && st.start.len == 3 * n && st.vel.len == 2 * n &&
                 st.travel.len == n && st.last_contact.len == n && st.g.len == n &&
                 st.clear.len == n && st.acc.len == 3 * n && st.acc_abs.len == 3 * n &&
                 st.acc_raw.len == 3 * n && st.acc_obs.len == n &&
                 st.acc_pred.len == n && st.acc_t.len == n && st.acc_rot.len == n &&
                 st.acc_rot0.len == n && st.isolating.len == n && st.age.len == n &&
                 st.gate.len == n && st.acc_n.len == n && st.pending.len == n &&
                 st.detected.len == n && a.seen.len == 3 * n &&
                 (!a.fresh.b || a.fresh.len == n) &&
                 (!a.contact.b || a.contact.len == n) && a.commands.len == 2 * n &&
                 a.motor_accel.len == n && a.turn_accel.len == n && a.brake.len == n &&
                 a.read.len == n && a.cleared.len == n && a.alarms.len == n &&
                 (a.trace_rows.q == NULL) == (a.trace_inc.f == NULL) &&
                 (!a.trace_rows.q || (a.trace_rows.len == n && a.trace_inc.len == n));
    /* the rings: L rows of n poses and flags, the slot one of them */
    const Py_ssize_t slot = a.slot.n;
    double *ring = NULL;
    char *ring_fresh = NULL;
    if (shapes && (a.ring_values.f || a.ring_fresh.b)) {
        Py_ssize_t rows = n ? a.ring_fresh.len / n : 0;
        shapes = a.ring_values.f && a.ring_fresh.b && n > 0 &&
                 a.ring_fresh.len == rows * n && a.ring_values.len == 3 * rows * n &&
                 slot >= 0 && slot < rows;
        if (shapes) {
            ring = a.ring_values.f + 3 * n * slot;
            ring_fresh = (char *)a.ring_fresh.b + n * slot;
        }
    }
    if (!shapes) {
        PyErr_SetString(PyExc_ValueError, "residual_period: shapes differ");
        goto done;
    }
    double *pose = st.pose.f, *start = st.start.f, *vel = st.vel.f;
    double *rate = st.rate.f, *travel = st.travel.f;
    double *last_contact = st.last_contact.f, *g = st.g.f;
    double *clear = st.clear.f, *acc = st.acc.f, *acc_abs = st.acc_abs.f;
    double *acc_raw = st.acc_raw.f, *acc_obs = st.acc_obs.f;
    double *acc_pred = st.acc_pred.f, *acc_t = st.acc_t.f;
    double *acc_rot = st.acc_rot.f, *acc_rot0 = st.acc_rot0.f;
    double *isolating = st.isolating.f;
    int64_t *age = st.age.q, *gate = st.gate.q, *acc_n = st.acc_n.q;
    char *pending = (char *)st.pending.b, *detected = (char *)st.detected.b;
    const double *seen = a.seen.f, *cmd = a.commands.f;
    const char *fresh = (const char *)a.fresh.b;
    const char *contact = (const char *)a.contact.b;
    const double *accel = a.motor_accel.f, *turn = a.turn_accel.f;
    const double *brake = a.brake.f;
    int64_t *read = a.read.q, *cleared = a.cleared.q;
    int64_t *alarms = a.alarms.q;
    int64_t *trace_rows = a.trace_rows.q;
    double *trace_inc = a.trace_inc.f;

    double t = a.t.x, h = a.h.x, sp = a.sp.x, sh = a.sh.x, sigma_h = a.heading_noise.x;
    double mu = a.mu.x, lam = a.lam.x, isolation = a.isolation.x, settle = a.settle.x;
    double half_mu2 = 0.5 * mu * mu;
    double dts = h / (double)substeps;
    /* Python's max(isolation, braking + window dt + settle) past the alarm */
    double window_s = (double)window * h;
    Py_ssize_t n_read = 0, n_cleared = 0, n_alarms = 0, n_used = 0;

    for (Py_ssize_t i = 0; i < n; i++) {
        double *p = pose + 3 * i, *st = start + 3 * i;
        const double *o = seen + 3 * i;
        int is_fresh = fresh == NULL || fresh[i];
        if (ring != NULL) { /* the history's row of this period */
            ring[3 * i] = o[0];
            ring[3 * i + 1] = o[1];
            ring[3 * i + 2] = o[2];
            ring_fresh[i] = (char)is_fresh;
        }
        motor_period(p, vel + 2 * i, rate + i, travel + i, cmd[2 * i],
                     cmd[2 * i + 1], accel[i], turn[i], h, dts, substeps);
        age[i] += 1;
        /* a window starts from a new observation */
        if (pending[i] && is_fresh) {
            p[0] = st[0] = o[0];
            p[1] = st[1] = o[1];
            p[2] = st[2] = o[2];
            age[i] = 0;
            travel[i] = 0.0;
            pending[i] = 0;
        }
        int touching = contact != NULL && contact[i];
        if (touching) {
            last_contact[i] = t;
        }
        /* a window touching a contact, or the one after it, is skipped */
        gate[i] = touching ? 2 * window : (gate[i] - 1 > 0 ? gate[i] - 1 : 0);
        if (!(age[i] >= window && is_fresh && !pending[i])) {
            continue;
        }
        /* the residual in the frame of the predicted heading */
        double d0 = o[0] - p[0], d1 = o[1] - p[1];
        double c = cos(p[2]), sn = sin(p[2]);
        double raw[3] = {c * d0 + sn * d1, -sn * d0 + c * d1, wrapped(o[2] - p[2])};
        double moved = travel[i] * sigma_h;
        double sc = sqrt(sp * sp + moved * moved);
        double z[3] = {raw[0] / sp, raw[1] / sc, raw[2] / sh};
        int gated = gate[i] > 0;
        pending[i] = 1; /* the next window starts at the next observation */
        if (gated) {
            continue;
        }
        double inc = llr(hypot(hypot(z[0], z[1]), z[2]), mu, half_mu2);
        if (trace_rows != NULL) {
            trace_rows[n_used] = i;
            trace_inc[n_used] = inc;
        }
        n_used++;
        double observed = hypot(o[0] - st[0], o[1] - st[1]);
        double rotation = wrapped(o[2] - st[2]);
        double seconds = (double)age[i] * h;
        int add = 0;
        if (detected[i]) {
            if (t <= isolating[i] + 1e-9) { /* the kind from more residuals */
                add = 1;
                read[n_read++] = i;
            }
        }
        else {
            if (g[i] <= 0.0) { /* g left 0: new sums */
                for (int k = 0; k < 3; k++) {
                    acc[3 * i + k] = acc_abs[3 * i + k] = acc_raw[3 * i + k] = 0.0;
                }
                acc_obs[i] = acc_pred[i] = acc_t[i] = acc_rot[i] = 0.0;
                acc_n[i] = 0;
            }
            g[i] = floored(g[i] + inc);
            add = g[i] > 0.0;
        }
        if (add) { /* _accumulate */
            for (int k = 0; k < 3; k++) {
                acc[3 * i + k] = acc[3 * i + k] + z[k];
                acc_abs[3 * i + k] = acc_abs[3 * i + k] + fabs(z[k]);
                acc_raw[3 * i + k] = acc_raw[3 * i + k] + raw[k];
            }
            acc_obs[i] = acc_obs[i] + observed;
            acc_pred[i] = acc_pred[i] + travel[i];
            acc_t[i] = acc_t[i] + seconds;
            if (acc_n[i] == 0) {
                acc_rot0[i] = rotation;
            }
            acc_rot[i] = acc_rot[i] + rotation;
            acc_n[i] += 1;
        }
        if (detected[i]) { /* the clearing statistic */
            clear[i] = floored(clear[i] - inc);
            if (clear[i] >= lam) {
                detected[i] = 0;
                clear[i] = 0.0;
                cleared[n_cleared++] = i;
            }
        }
        else if (g[i] >= lam) { /* an alarm: latched, its kind read until then */
            detected[i] = 1;
            double braking = hypot(vel[2 * i], vel[2 * i + 1]) / brake[i];
            double after = braking + window_s + settle;
            isolating[i] = t + (after > isolation ? after : isolation);
            g[i] = 0.0;
            clear[i] = 0.0;
            alarms[n_alarms++] = i;
        }
    }
    result = Py_BuildValue("(nnnn)", n_read, n_cleared, n_alarms, n_used);
done:
    release_named(&detector_state_signature, (Arg *)&st);
    release_named(&residual_period_signature, (Arg *)&a);
    return result;
}

static PyMethodDef methods[] = {
    {"residual_period", (PyCFunction)(void (*)(void))residual_period,
     METH_FASTCALL | METH_KEYWORDS, residual_period_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_residual",
    "The residual detector's pass of a control period in C (see residual_kernel.py).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__residual(void)
{
    return PyModule_Create(&module);
}
