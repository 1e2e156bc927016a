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
#define CHI_REST 0.001
#define PARK_RADIUS 0.25 /* flatness.PARK_RADIUS */
#define TRAVEL_NONE 0
#define TRAVEL_FORWARD 1
#define TRAVEL_BACKWARD (-1)

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

/* parking, one row: whether the target ``target`` (a NaN coordinate aims at the
 * position's) rests (``|v_ref| < CHI_REST``) within PARK_RADIUS of ``pos``. */
static inline int
parking_row(const double *pos, const double *target, const double *v_ref)
{
    double a0 = isnan(target[0]) ? 0.0 : target[0] - pos[0];
    double a1 = isnan(target[1]) ? 0.0 : target[1] - pos[1];
    return a0 * a0 + a1 * a1 < PARK_RADIUS * PARK_RADIUS &&
           v_ref[0] * v_ref[0] + v_ref[1] * v_ref[1] < CHI_REST * CHI_REST;
}

/* travel_direction, one row: the direction of travel for chi ``x`` of the next
 * period, from chi ``c`` now and the direction ``travel`` now (heading's cosine and
 * sine ``cth``, ``sth``); backward only where the row ``parks``. */
static inline int
travel_row(const double *c, const double *x, double cth, double sth, int travel,
           int parks)
{
    double n1 = x[0], n2 = x[1];
    if (!(n1 * n1 + n2 * n2 >= CHI_REST * CHI_REST)) {
        return travel; /* chi_next at rest: unchanged */
    }
    double c1 = c[0], c2 = c[1];
    int vanished = (c1 * c1 + c2 * c2 < CHI_REST * CHI_REST) || (c1 * n1 + c2 * n2 < 0.0);
    double ahead = n1 * cth + n2 * sth;
    int out = travel;
    if (vanished) {
        out = travel == TRAVEL_NONE ? TRAVEL_FORWARD
                                    : (ahead < 0.0 ? TRAVEL_BACKWARD : TRAVEL_FORWARD);
    }
    if ((out == TRAVEL_BACKWARD && ahead > 0.0) || !parks) {
        out = TRAVEL_FORWARD;
    }
    return out == TRAVEL_NONE ? TRAVEL_FORWARD : out;
}

/* limit_turn (where ``turning_limit``) about the direction of travel ``travel_next``,
 * the applied rate, flat_inputs with the direction ``travel`` now (``angle_chi`` the
 * angle of ``chi``) and the clip of v2, one row: writes chi_next (2), v1 and v2, and
 * returns the direction of travel of the next period. */
static inline int
flat_row(double th, double cth, double sth, const double *c, const double *x,
         double norm, double angle_chi, double k, double turn, double vmax, double dt,
         int turning_limit, int travel, int travel_next, double *chi_next,
         double *v1_out, double *v2_out)
{
    double out0 = x[0], out1 = x[1];
    double aim = NAN;
    if (turning_limit) { /* limit_turn */
        int back = travel_next == TRAVEL_BACKWARD;
        double angle = atan2(x[1], x[0]);
        if (back) {
            angle = angle + M_PI;
        }
        double off = wrap_angle(angle - th);
        double lim = turn * dt;
        int outside = (fabs(off) > lim) && (norm >= CHI_REST);
        if (outside) {
            double edge = clamp(off, -lim, lim);
            double along = larger(norm * cos(off - edge), 0.0);
            if (back) {
                along = -along;
            }
            double direction = th + edge;
            out0 = along * cos(direction);
            out1 = along * sin(direction);
            aim = angle;
        }
        if (hypot(out0, out1) < CHI_REST) { /* held at rest: it has not set off */
            travel_next = travel;
        }
    }
    chi_next[0] = out0;
    chi_next[1] = out1;
    double cd0 = (out0 - c[0]) / dt, cd1 = (out1 - c[1]) / dt;
    /* flat_inputs, eq. (5) */
    double c1 = c[0], c2 = c[1];
    double norm2 = c1 * c1 + c2 * c2;
    double v1 = sqrt(norm2);
    int moving = norm2 >= CHI_REST * CHI_REST;
    double safe = larger(norm2, CHI_REST * CHI_REST);
    double feedforward = (-c2 * cd0 + c1 * cd1) / safe;
    double angle = angle_chi;
    if (travel == TRAVEL_BACKWARD) { /* eq. (5) for -chi */
        v1 = -v1;
        angle = angle + M_PI;
    }
    double v2 = feedforward - k * wrap_angle(th - angle);
    if (!moving) { /* at rest: the heading held, the motion along it */
        v1 = c1 * cth + c2 * sth;
        v2 = 0.0;
        feedforward = 0.0;
    }
    if (aim == aim) { /* turning: toward the aim the turn limit held chi from */
        double toward = -k * wrap_angle(th - aim);
        v2 = feedforward + toward;
    }
    *v1_out = v1;
    *v2_out = clamp(v2, -vmax, vmax);
    return travel_next;
}

/* The arguments of controller_step, by name (accel.h): the gains and limits (n,) or
 * (1,) (one value for every row). */
#define CONTROLLER_STEP(X)                                                         \
    X(pos, FLOATS, 0)                                                              \
    X(chi, FLOATS, 0)                                                              \
    X(theta, FLOATS, 0)                                                            \
    X(target, FLOATS, 0)                                                           \
    X(v_ref, FLOATS, 0)                                                            \
    X(a_ref, FLOATS, 0)                                                            \
    X(k1, FLOATS, 0)                                                               \
    X(k2, FLOATS, 0)                                                               \
    X(k3, FLOATS, 0)                                                               \
    X(k4, FLOATS, 0)                                                               \
    X(accel_max, FLOATS, 0)                                                        \
    X(v1_max, FLOATS, 0)                                                           \
    X(kp, FLOATS, 0)                                                               \
    X(turn_max, FLOATS, 0)                                                         \
    X(v2_max, FLOATS, 0)                                                           \
    X(chi_next, FLOATS, WRITTEN)                                                   \
    X(v1, FLOATS, WRITTEN)                                                         \
    X(v2, FLOATS, WRITTEN)                                                         \
    X(travel, BYTES, 0)                                                            \
    X(travel_next, BYTES, WRITTEN)                                                 \
    X(dt, NUMBER, 0)                                                               \
    X(turning, INTEGER, 0)
NAMED(controller_step, CONTROLLER_STEP)

PyDoc_STRVAR(controller_step_doc,
"controller_step(*, pos, chi, theta, target, v_ref, a_ref, k1, k2, k3, k4,\n"
"                accel_max, v1_max, kp, turn_max, v2_max, chi_next, v1, v2, travel,\n"
"                travel_next, dt, turning) -> None\n"
"\n"
"The flatness controller of a period for n vehicles, by keywords only: ``pos, chi,\n"
"target, v_ref, a_ref`` (n, 2) float64 (a NaN target coordinate aims at the\n"
"position's), ``theta`` (n,), the gains, limits and ``kp`` (n,) or (1,), ``travel``\n"
"(n,) int8 (the direction of travel now), ``dt`` [s], ``turning`` true where the\n"
"turn rate is limited (anti-windup). Writes ``chi_next`` (n, 2), ``v1``, ``v2`` (n,)\n"
"and ``travel_next`` (n,) int8: eq. (6)'s Euler step with its clamps, the direction\n"
"of travel, the turn limit, eq. (5) and the clip of v2 to ``v2_max``.");

static PyObject *
controller_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
                PyObject *kwnames)
{
    controller_step_args a;
    if (parse_named(&controller_step_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    const double dt = a.dt.x;
    const int turning_limit = a.turning.n != 0;
    const Arg *k1 = &a.k1, *k2 = &a.k2, *k3 = &a.k3, *k4 = &a.k4;
    const Arg *accel = &a.accel_max, *v1_max = &a.v1_max, *kp = &a.kp;
    const Arg *turn = &a.turn_max, *v2_max = &a.v2_max;
    const Py_ssize_t n = a.theta.len;
    const Arg *gains[] = {k1, k2, k3, k4, accel, v1_max, kp, turn, v2_max};
    int shapes = a.pos.len == 2 * n && a.chi.len == 2 * n && a.target.len == 2 * n &&
                 a.v_ref.len == 2 * n && a.a_ref.len == 2 * n &&
                 a.chi_next.len == 2 * n && a.v1.len == n && a.v2.len == n &&
                 a.travel.len == n && a.travel_next.len == n;
    for (int g = 0; g < 9 && shapes; g++) {
        shapes = gains[g]->len == n || gains[g]->len == 1;
    }
    if (!shapes) {
        release_named(&controller_step_signature, (Arg *)&a);
        PyErr_SetString(PyExc_ValueError, "controller_step: shapes differ");
        return NULL;
    }
    const double *pos = a.pos.f, *chi = a.chi.f, *theta = a.theta.f;
    const double *target = a.target.f, *v_ref = a.v_ref.f, *a_ref = a.a_ref.f;
    const signed char *travel = (const signed char *)a.travel.b;
    signed char *travel_next = (signed char *)a.travel_next.b;
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *c = chi + 2 * i;
        double th = theta[i];
        double cth = cos(th), sth = sin(th);
        double nxt[2], norm;
        extension_row(pos + 2 * i, c, target + 2 * i, v_ref + 2 * i, a_ref + 2 * i,
                      k1->f[i * k1->step], k2->f[i * k2->step], k3->f[i * k3->step],
                      k4->f[i * k4->step], accel->f[i * accel->step],
                      v1_max->f[i * v1_max->step], dt, nxt, &norm);
        int now = travel[i];
        int parks = parking_row(pos + 2 * i, target + 2 * i, v_ref + 2 * i);
        int next = travel_row(c, nxt, cth, sth, now, parks);
        double angle_chi = atan2(c[1], c[0]);
        travel_next[i] = (signed char)flat_row(
            th, cth, sth, c, nxt, norm, angle_chi, kp->f[i * kp->step],
            turn->f[i * turn->step], v2_max->f[i * v2_max->step], dt, turning_limit,
            now, next, a.chi_next.f + 2 * i, a.v1.f + i, a.v2.f + i);
    }
    release_named(&controller_step_signature, (Arg *)&a);
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
    {"controller_step", (PyCFunction)(void (*)(void))controller_step,
     METH_FASTCALL | METH_KEYWORDS, controller_step_doc},
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
