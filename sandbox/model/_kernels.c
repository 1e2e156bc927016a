/* The flatness controller of one control period, row by row, in one C call, and the
 * residual detector's motor model of a period in one.
 *
 * sandbox/model/kernels.py calls these where this optional extension is built (the
 * compiled path ``controller`` of sandbox/accel.py). controller_step does for every
 * vehicle what the numpy functions of sandbox/model/flatness.py do as the loop calls
 * them (extension_rate, advance_extension, limit_turn, flat_inputs and the clip of
 * v2); motor_model what sandbox/behaviour/detection.py's numpy motor model does. The
 * C library's sqrt, hypot, sin, cos and atan2; the numbers agree with the numpy
 * functions within the tolerance of sandbox/accel.py.
 *
 * Arrays are C-contiguous float64; a parameter array of length 1 is one value for
 * every row (stride 0). Every pointer argument is an object with the buffer
 * interface (a numpy array).
 */

#include "accel.h"
#include "motor_model.h"

/* The controller's constants (sandbox/model/flatness.py). */
#define CHI_HOLD 1e-3
#define CHI_REG 0.01

/* sandbox.model.dynamics.wrap_angle: wrapped into [-pi, pi), pi folded to -pi. */
static inline double
wrap_angle(double a)
{
    double w = wrapped(a);
    return (w >= M_PI) ? -M_PI : w;
}

/* Eq. (6) and the Euler step of advance_extension with its two clamps, one row:
 * writes chi before the turn limit to ``nxt`` (2) and its norm to ``norm``. */
static inline void
extension_row(const double *p, const double *c, const double *g, const double *vr,
              const double *ar, double k1, double k2, double k3, double k4,
              double accel, double vmax, double dt, double *nxt, double *norm_out)
{
    double aim0 = (g[0] != g[0]) ? p[0] : g[0];
    double aim1 = (g[1] != g[1]) ? p[1] : g[1];
    /* eq. (6): k_pos (pos - aim) + k_vel (chi - v_ref) + a_ref */
    double d0 = k1 * (p[0] - aim0) + k2 * (c[0] - vr[0]);
    double d1 = k3 * (p[1] - aim1) + k4 * (c[1] - vr[1]);
    d0 = d0 + ar[0];
    d1 = d1 + ar[1];
    double s0 = d0 * dt, s1 = d1 * dt;
    double step_norm = hypot(s0, s1);
    double limit = accel * dt;
    if (step_norm > limit) {
        double scale = limit / larger(step_norm, 1e-300);
        s0 = s0 * scale;
        s1 = s1 * scale;
    }
    double x0 = c[0] + s0, x1 = c[1] + s1;
    double norm = hypot(x0, x1);
    if (norm > vmax) {
        double scale = vmax / larger(norm, 1e-300);
        x0 = x0 * scale;
        x1 = x1 * scale;
        norm = hypot(x0, x1);
    }
    nxt[0] = x0;
    nxt[1] = x1;
    *norm_out = norm;
}

/* limit_turn (where ``turning_limit``; ``angle_nxt`` the angle of ``nxt``), the
 * applied rate, flat_inputs (``angle_chi`` the angle of ``chi``) and the clip of v2,
 * one row: writes chi_next (2), v1 and v2. */
static inline void
flat_row(double th, const double *c, const double *x, double norm, double angle_nxt,
         double angle_chi, double k, double turn, double vmax, double dt, long flags,
         double *chi_next, double *v1_out, double *v2_out)
{
    int turning_limit = (int)(flags & 1);
    double out0 = x[0], out1 = x[1];
    double aim = NAN;
    if (turning_limit) { /* limit_turn */
        double off = wrap_angle(angle_nxt - th);
        double lim = turn * dt;
        int outside = (fabs(off) > lim) && (norm >= CHI_HOLD);
        if (outside) {
            double edge = clamp(off, -lim, lim);
            double along = larger(norm * cos(off - edge), 0.0);
            double direction = th + edge;
            out0 = along * cos(direction);
            out1 = along * sin(direction);
            aim = angle_nxt;
        }
    }
    chi_next[0] = out0;
    chi_next[1] = out1;
    double cd0 = (out0 - c[0]) / dt, cd1 = (out1 - c[1]) / dt;
    /* flat_inputs, eq. (5) */
    double c1 = c[0], c2 = c[1];
    double norm2 = c1 * c1 + c2 * c2;
    double v1 = sqrt(norm2);
    int defined = norm2 >= CHI_HOLD * CHI_HOLD;
    double safe = larger(norm2, CHI_REG * CHI_REG);
    double feedforward = (-c2 * cd0 + c1 * cd1) / safe;
    double heading_error = wrap_angle(th - angle_chi);
    double v2 = defined ? feedforward - k * heading_error : 0.0;
    if (aim == aim) { /* turning: toward the aim the turn limit held chi from */
        double toward = -k * wrap_angle(th - aim);
        v2 = (defined ? feedforward : 0.0) + toward;
    }
    v2 = clamp(v2, -vmax, vmax);
    *v1_out = defined ? v1 : 0.0;
    *v2_out = v2;
}

PyDoc_STRVAR(controller_step_doc,
"controller_step(pos, chi, theta, target, v_ref, a_ref, k1, k2, k3, k4, accel_max,\n"
"                v1_max, kp, turn_max, v2_max, dt, flags, chi_next, v1, v2) -> None\n"
"\n"
"The flatness controller of a period for n vehicles: ``pos, chi, target, v_ref,\n"
"a_ref`` (n, 2) (a NaN target coordinate aims at the position's), ``theta`` (n,),\n"
"the gains, limits and ``kp`` (n,) or (1,), ``dt`` [s], ``flags & 1`` where the\n"
"turn rate is limited (anti-windup). Writes ``chi_next`` (n, 2), ``v1`` and ``v2``\n"
"(n,): eq. (6)'s Euler step with its clamps, the turn limit, eq. (5) and the clip\n"
"of v2 to ``v2_max``.");

static PyObject *
controller_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 20) {
        PyErr_SetString(PyExc_TypeError, "controller_step takes 20 arguments");
        return NULL;
    }
    double dt = PyFloat_AsDouble(args[15]);
    long flags = PyLong_AsLong(args[16]);
    if ((dt == -1.0 || flags == -1) && PyErr_Occurred()) {
        return NULL;
    }
    Rows r[18];
    int got = 0;
    for (int k = 0; k < 20; k++) {
        if (k == 15 || k == 16) {
            continue;
        }
        int idx = k < 15 ? k : k - 2;
        if (get_rows(args[k], &r[idx], k >= 17) < 0) {
            release(r, got);
            return NULL;
        }
        got++;
    }
    Rows *pos = &r[0], *chi = &r[1], *theta = &r[2], *target = &r[3];
    Rows *v_ref = &r[4], *a_ref = &r[5], *k1 = &r[6], *k2 = &r[7], *k3 = &r[8];
    Rows *k4 = &r[9], *accel = &r[10], *v1_max = &r[11], *kp = &r[12];
    Rows *turn = &r[13], *v2_max = &r[14], *chi_next = &r[15], *v1_out = &r[16];
    Rows *v2_out = &r[17];
    Py_ssize_t n = theta->len;
    if (pos->len != 2 * n || chi->len != 2 * n || target->len != 2 * n ||
        v_ref->len != 2 * n || a_ref->len != 2 * n || chi_next->len != 2 * n ||
        v1_out->len != n || v2_out->len != n) {
        release(r, got);
        PyErr_SetString(PyExc_ValueError, "controller_step: shapes differ");
        return NULL;
    }
    int turning_limit = (int)(flags & 1);
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *c = chi->data + 2 * i;
        double nxt[2], norm;
        extension_row(pos->data + 2 * i, c, target->data + 2 * i, v_ref->data + 2 * i,
                      a_ref->data + 2 * i, k1->data[i * k1->step],
                      k2->data[i * k2->step], k3->data[i * k3->step],
                      k4->data[i * k4->step], accel->data[i * accel->step],
                      v1_max->data[i * v1_max->step], dt, nxt, &norm);
        double angle_chi = atan2(c[1], c[0]);
        double angle_nxt = turning_limit ? atan2(nxt[1], nxt[0]) : 0.0;
        flat_row(theta->data[i], c, nxt, norm, angle_nxt, angle_chi,
                 kp->data[i * kp->step], turn->data[i * turn->step],
                 v2_max->data[i * v2_max->step], dt, flags, chi_next->data + 2 * i,
                 v1_out->data + i, v2_out->data + i);
    }
    release(r, got);
    Py_RETURN_NONE;
}

PyDoc_STRVAR(motor_model_doc,
"motor_model(pose, vel, rate, commands, accel, turn_accel, h, substeps, travel)\n"
"    -> None\n"
"\n"
"One control period of the residual detector's motor model\n"
"(sandbox/behaviour/detection.py, _advance_model) for n vehicles: ``pose`` (n, 3),\n"
"``vel`` (n, 2), ``rate`` (n,) and ``travel`` (n,) advanced in place from the\n"
"commands ``(v1, v2)`` (n, 2), the motors' limits ``accel`` and ``turn_accel`` (n,)\n"
"[m/s^2, rad/s^2], the period ``h`` [s] in ``substeps``.");

static PyObject *
motor_model(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 9) {
        PyErr_SetString(PyExc_TypeError, "motor_model takes 9 arguments");
        return NULL;
    }
    double h = PyFloat_AsDouble(args[6]);
    long substeps = PyLong_AsLong(args[7]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    static const int at[] = {0, 1, 2, 3, 4, 5, 8};
    Rows r[7];
    int got = 0;
    for (int k = 0; k < 7; k++) {
        int writable = at[k] <= 2 || at[k] == 8;
        if (get_rows(args[at[k]], &r[k], writable) < 0) {
            release(r, got);
            return NULL;
        }
        got++;
    }
    Rows *pose = &r[0], *vel = &r[1], *rate = &r[2], *cmd = &r[3];
    Rows *accel = &r[4], *turn = &r[5], *travel = &r[6];
    Py_ssize_t n = rate->len;
    if (pose->len != 3 * n || vel->len != 2 * n || cmd->len != 2 * n ||
        accel->len != n || turn->len != n || travel->len != n || substeps < 1) {
        release(r, got);
        PyErr_SetString(PyExc_ValueError, "motor_model: shapes differ");
        return NULL;
    }
    double dts = h / (double)substeps;
    for (Py_ssize_t i = 0; i < n; i++) {
        motor_period(pose->data + 3 * i, vel->data + 2 * i, rate->data + i,
                     travel->data + i, cmd->data[2 * i], cmd->data[2 * i + 1],
                     accel->data[i], turn->data[i], h, dts, substeps);
    }
    release(r, got);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"controller_step", (PyCFunction)(void (*)(void))controller_step, METH_FASTCALL,
     controller_step_doc},
    {"motor_model", (PyCFunction)(void (*)(void))motor_model, METH_FASTCALL,
     motor_model_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "The controller and the motor model of one period in C (see kernels.py).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__kernels(void)
{
    return PyModule_Create(&module);
}
