/* The tracking motors' force limits of a period (motor_limits) in one C call.
 *
 * sandbox/physics/world.py calls this where this optional extension is built (the
 * compiled path ``motors`` of sandbox/accel.py): for every vehicle, the force that takes its body from the velocity
 * read to the commanded one within one substep (with the headroom; zero in contact),
 * bounded below by the least force, and whether its joints must change (the limit
 * grows, or can shrink by half), with the C library's hypot.
 */

#include "accel.h"

/* The arguments of motor_limits, by name (accel.h). */
#define MOTOR_LIMITS(X)                                                            \
    X(command, FLOATS, 0)                                                          \
    X(measured, FLOATS, 0)                                                         \
    X(free, BYTES, 0)                                                              \
    X(substep, NUMBER, 0)                                                          \
    X(headroom, NUMBER, 0)                                                         \
    X(mass, FLOATS, 0)                                                             \
    X(moment, FLOATS, 0)                                                           \
    X(least_force, FLOATS, 0)                                                      \
    X(least_torque, FLOATS, 0)                                                     \
    X(force, FLOATS, 0)                                                            \
    X(torque, FLOATS, 0)                                                           \
    X(tracking, BYTES, 0)                                                          \
    X(force_out, FLOATS, WRITTEN)                                                  \
    X(torque_out, FLOATS, WRITTEN)                                                 \
    X(change, BYTES, WRITTEN)
NAMED(motor_limits, MOTOR_LIMITS)

PyDoc_STRVAR(motor_limits_doc,
"motor_limits(*, command, measured, free, substep, headroom, mass, moment,\n"
"             least_force, least_torque, force, torque, tracking, force_out,\n"
"             torque_out, change) -> int\n"
"\n"
"``command``, ``measured`` (n, 3); ``free``, ``tracking`` and ``change`` (n,) bool;\n"
"the rest (n,) float64. Writes the new limits to ``force_out``, ``torque_out`` and\n"
"sets ``change`` where a tracking vehicle's joints must change; returns how many\n"
"do.");

static PyObject *
motor_limits(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
             PyObject *kwnames)
{
    motor_limits_args a;
    if (parse_named(&motor_limits_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    Py_ssize_t n = a.mass.len;
    if (a.command.len != 3 * n || a.measured.len != 3 * n || a.free.len != n ||
        a.moment.len != n || a.least_force.len != n || a.least_torque.len != n ||
        a.force.len != n || a.torque.len != n || a.tracking.len != n ||
        a.force_out.len != n || a.torque_out.len != n || a.change.len != n) {
        PyErr_SetString(PyExc_ValueError, "motor_limits: shapes differ");
        goto done;
    }
    const double substep = a.substep.x, headroom = a.headroom.x;
    const double *cmd = a.command.f, *meas = a.measured.f;
    const double *mass = a.mass.f, *moment = a.moment.f;
    const double *least_f = a.least_force.f, *least_t = a.least_torque.f;
    const double *cur_f = a.force.f, *cur_t = a.torque.f;
    double *force = a.force_out.f, *torque = a.torque_out.f;
    const unsigned char *free_ = a.free.b, *tracking = a.tracking.b;
    unsigned char *change = a.change.b;
    Py_ssize_t changed = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        double d0 = cmd[3 * i] - meas[3 * i];
        double d1 = cmd[3 * i + 1] - meas[3 * i + 1];
        double d2 = cmd[3 * i + 2] - meas[3 * i + 2];
        double linear = (free_[i] ? hypot(d0, d1) : 0.0) / substep;
        double angular = (free_[i] ? fabs(d2) : 0.0) / substep;
        double fi = larger(least_f[i], headroom * mass[i] * linear);
        double ti = larger(least_t[i], headroom * moment[i] * angular);
        int grow = (fi > cur_f[i]) || (ti > cur_t[i]);
        int shrink = (fi < 0.5 * cur_f[i]) || (ti < 0.5 * cur_t[i]);
        force[i] = fi;
        torque[i] = ti;
        change[i] = tracking[i] && (grow || shrink);
        changed += change[i];
    }
    result = PyLong_FromSsize_t(changed);
done:
    release_named(&motor_limits_signature, (Arg *)&a);
    return result;
}

static PyMethodDef methods[] = {
    {"motor_limits", (PyCFunction)(void (*)(void))motor_limits,
     METH_FASTCALL | METH_KEYWORDS, motor_limits_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_motors",
    "The tracking motors' force limits in C (see sandbox/physics/world.py).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__motors(void)
{
    return PyModule_Create(&module);
}
