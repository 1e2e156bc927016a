/* The tracking motors' force limits of a period (motor_limits) in one C call.
 *
 * sandbox/physics/world.py calls this where this optional extension is built (the
 * compiled path ``motors`` of sandbox/accel.py): for every vehicle, the force that takes its body from the velocity
 * read to the commanded one within one substep (with the headroom; zero in contact),
 * bounded below by the least force, and whether its joints must change (the limit
 * grows, or can shrink by half), with the C library's hypot.
 */

#include "accel.h"

/* A bool array (numpy's, one byte an element) and its length. */
static int
get_flags(PyObject *obj, Py_buffer *view, int writable)
{
    if (get_bytes(obj, view, writable) < 0) {
        return -1;
    }
    if (view->itemsize != 1) {
        PyBuffer_Release(view);
        PyErr_SetString(PyExc_TypeError, "expected a contiguous bool array");
        return -1;
    }
    return 0;
}

PyDoc_STRVAR(motor_limits_doc,
"motor_limits(command, measured, free, substep, headroom, mass, moment,\n"
"             least_force, least_torque, force, torque, tracking, force_out,\n"
"             torque_out, change) -> int\n"
"\n"
"``command``, ``measured`` (n, 3); ``free``, ``tracking`` and ``change`` (n,) bool;\n"
"the rest (n,) float64. Writes the new limits to ``force_out``, ``torque_out`` and\n"
"sets ``change`` where a tracking vehicle's joints must change; returns how many\n"
"do.");

static PyObject *
motor_limits(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 15) {
        PyErr_SetString(PyExc_TypeError, "motor_limits takes 15 arguments");
        return NULL;
    }
    double substep = PyFloat_AsDouble(args[3]);
    double headroom = PyFloat_AsDouble(args[4]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    /* float arrays: 0 command, 1 measured, 5..10 and 12, 13; flags: 2, 11, 14 */
    static const int float_at[] = {0, 1, 5, 6, 7, 8, 9, 10, 12, 13};
    static const int flag_at[] = {2, 11, 14};
    Rows r[10];
    Py_buffer f[3];
    int got_r = 0, got_f = 0;
    PyObject *result = NULL;
    for (int k = 0; k < 10; k++) {
        if (get_rows(args[float_at[k]], &r[k], float_at[k] >= 12) < 0) goto done;
        got_r++;
    }
    for (int k = 0; k < 3; k++) {
        if (get_flags(args[flag_at[k]], &f[k], k == 2) < 0) goto done;
        got_f++;
    }
    Py_ssize_t n = r[2].len;
    for (int k = 2; k < 10; k++) {
        if (r[k].len != n) {
            PyErr_SetString(PyExc_ValueError, "motor_limits: shapes differ");
            goto done;
        }
    }
    if (r[0].len != 3 * n || r[1].len != 3 * n || f[0].len != n || f[1].len != n ||
        f[2].len != n) {
        PyErr_SetString(PyExc_ValueError, "motor_limits: shapes differ");
        goto done;
    }
    const double *cmd = r[0].data, *meas = r[1].data;
    const double *mass = r[2].data, *moment = r[3].data;
    const double *least_f = r[4].data, *least_t = r[5].data;
    const double *cur_f = r[6].data, *cur_t = r[7].data;
    double *force = r[8].data, *torque = r[9].data;
    const unsigned char *free_ = f[0].buf, *tracking = f[1].buf;
    unsigned char *change = f[2].buf;
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
    release(r, got_r);
    for (int k = 0; k < got_f; k++) {
        PyBuffer_Release(&f[k]);
    }
    return result;
}

static PyMethodDef methods[] = {
    {"motor_limits", (PyCFunction)(void (*)(void))motor_limits, METH_FASTCALL,
     motor_limits_doc},
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
