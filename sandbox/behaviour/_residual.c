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

/* A buffer of one of the element types below, C-contiguous. */
enum { F64, I64, BOOL };

typedef struct {
    Py_buffer view;
    void *data;
    Py_ssize_t len; /* elements */
} Buf;

static int
get_buf(PyObject *obj, Buf *b, int type, int writable)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, &b->view, flags) < 0) {
        return -1;
    }
    const char *f = b->view.format;
    int ok = f != NULL;
    if (ok && type == F64) {
        ok = b->view.itemsize == 8 && strcmp(f, "d") == 0;
    }
    else if (ok && type == I64) {
        ok = b->view.itemsize == 8 && (strcmp(f, "l") == 0 || strcmp(f, "q") == 0);
    }
    else if (ok) {
        ok = b->view.itemsize == 1 && strcmp(f, "?") == 0;
    }
    if (!ok) {
        PyBuffer_Release(&b->view);
        PyErr_SetString(PyExc_TypeError, "residual_period: an array of a wrong type");
        return -1;
    }
    b->data = b->view.buf;
    b->len = b->view.len / b->view.itemsize;
    return 0;
}

/* The arrays: the state's fields (read by name), then the arguments after the state;
 * each one's type, whether written, and columns (0: optional rows of bools, None for
 * "all" or "none"). */
enum {
    POSE, START, VEL, RATE, TRAVEL, LAST_CONTACT, G, CLEAR, ACC, ACC_ABS, ACC_RAW,
    ACC_OBS, ACC_PRED, ACC_T, ACC_ROT, ACC_ROT0, ISOLATING, AGE, GATE, ACC_N,
    PENDING, DETECTED, N_FIELDS = DETECTED + 1,
    SEEN = N_FIELDS, FRESH, CONTACT, COMMANDS, MOTOR_ACCEL, TURN_ACCEL, BRAKE, READ,
    CLEARED, ALARMS, TRACE_ROWS, TRACE_INC, RING_VALUES, RING_FRESH, N_ARRAYS
};

static const char *FIELDS[N_FIELDS] = {
    "pose", "start", "vel", "rate", "travel", "last_contact", "g", "clear", "acc",
    "acc_abs", "acc_raw", "acc_obs", "acc_pred", "acc_t", "acc_rot", "acc_rot0",
    "isolating", "age", "gate", "acc_n", "pending", "detected",
};
static PyObject *field_names[N_FIELDS]; /* interned at the module's import */

static const struct {
    int type, writable, columns;
} SPEC[N_ARRAYS] = {
    [POSE] = {F64, 1, 3}, [START] = {F64, 1, 3}, [VEL] = {F64, 1, 2},
    [RATE] = {F64, 1, 1}, [TRAVEL] = {F64, 1, 1}, [LAST_CONTACT] = {F64, 1, 1},
    [G] = {F64, 1, 1}, [CLEAR] = {F64, 1, 1}, [ACC] = {F64, 1, 3},
    [ACC_ABS] = {F64, 1, 3}, [ACC_RAW] = {F64, 1, 3}, [ACC_OBS] = {F64, 1, 1},
    [ACC_PRED] = {F64, 1, 1}, [ACC_T] = {F64, 1, 1}, [ACC_ROT] = {F64, 1, 1},
    [ACC_ROT0] = {F64, 1, 1}, [ISOLATING] = {F64, 1, 1}, [AGE] = {I64, 1, 1},
    [GATE] = {I64, 1, 1}, [ACC_N] = {I64, 1, 1}, [PENDING] = {BOOL, 1, 1},
    [DETECTED] = {BOOL, 1, 1}, [SEEN] = {F64, 0, 3}, [FRESH] = {BOOL, 0, 0},
    [CONTACT] = {BOOL, 0, 0}, [COMMANDS] = {F64, 0, 2}, [MOTOR_ACCEL] = {F64, 0, 1},
    [TURN_ACCEL] = {F64, 0, 1}, [BRAKE] = {F64, 0, 1}, [READ] = {I64, 1, 1},
    [CLEARED] = {I64, 1, 1}, [ALARMS] = {I64, 1, 1}, [TRACE_ROWS] = {I64, 1, 1},
    [TRACE_INC] = {F64, 1, 1}, [RING_VALUES] = {F64, 1, 3}, [RING_FRESH] = {BOOL, 1, 1},
};

/* The scalars, after the arrays. */
enum {
    SLOT, T, H, SUBSTEPS, WINDOW, SP, SH, HEADING_NOISE, MU, LAMBDA, ISOLATION, SETTLE,
    N_ARGS
};
/* The arguments: the state, the arrays after its fields, the scalars. */
#define N_PASSED (1 + N_ARRAYS - N_FIELDS + N_ARGS)

static void
release_bufs(Buf *b, const int *present, int count)
{
    for (int j = 0; j < count; j++) {
        if (present[j]) {
            PyBuffer_Release(&b[j].view);
        }
    }
}

PyDoc_STRVAR(residual_period_doc,
"residual_period(state, seen, fresh, contact, commands, motor_accel, turn_accel,\n"
"                brake, read, cleared, alarms, trace_rows, trace_inc, ring_values,\n"
"                ring_fresh, slot, t, h, substeps, window, sp, sh, heading_noise,\n"
"                mu, lam, isolation, settle) -> (reads, clears, alarms, used)\n"
"\n"
"Stores the observed poses and fresh flags in row ``slot`` of the track\n"
"history's rings ``ring_values`` (L, n, 3) and ``ring_fresh`` (L, n) (None: no\n"
"history), then does"
"one period of the residual detector for n rows: the arrays of the DetectorState\n"
"``state`` (float64, the ages, gates and counts int64, ``pending`` and\n"
"``detected`` bool) advance in place from the observations ``seen`` (n, 3),\n"
"``fresh`` and ``contact`` (n,) bool or None (every row fresh, none in contact),\n"
"the commands (n, 2) and the drives' limits (n,). Writes the rows read on while\n"
"isolating, the cleared rows and the alarms to ``read``, ``cleared`` and\n"
"``alarms`` (int64, n), and where ``trace_rows`` is not None the rows of every\n"
"window used and their log-likelihood ratios to it and ``trace_inc`` (n); returns\n"
"how many of each. ``window`` [periods], ``sp``, ``sh`` the residuals' standard\n"
"deviations, ``mu`` the shift, ``lam`` the threshold, ``isolation`` [s] and\n"
"``settle`` [s], how long the track must show a braked vehicle at rest.");

static PyObject *
residual_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != N_PASSED) {
        PyErr_Format(PyExc_TypeError, "residual_period takes %d arguments", N_PASSED);
        return NULL;
    }
    double s[N_ARGS];
    for (int k = 0; k < N_ARGS; k++) {
        s[k] = PyFloat_AsDouble(args[N_PASSED - N_ARGS + k]);
    }
    if (PyErr_Occurred()) {
        return NULL;
    }
    long substeps = (long)s[SUBSTEPS], window = (long)s[WINDOW];
    if (substeps < 1 || (double)substeps != s[SUBSTEPS] ||
        (double)window != s[WINDOW]) {
        PyErr_SetString(PyExc_ValueError, "residual_period: bad substeps or window");
        return NULL;
    }
    Buf b[N_ARRAYS];
    int present[N_ARRAYS];
    for (int k = 0; k < N_ARRAYS; k++) {
        PyObject *obj;
        if (k < N_FIELDS) { /* the state's field: a reference while it is read */
            obj = PyObject_GetAttr(args[0], field_names[k]);
            if (obj == NULL) {
                release_bufs(b, present, k);
                return NULL;
            }
        }
        else {
            obj = args[1 + k - N_FIELDS];
        }
        int optional = SPEC[k].columns == 0 || k == TRACE_ROWS || k == TRACE_INC ||
                       k == RING_VALUES || k == RING_FRESH;
        present[k] = !(optional && obj == Py_None);
        int failed =
            present[k] && get_buf(obj, &b[k], SPEC[k].type, SPEC[k].writable) < 0;
        if (k < N_FIELDS) {
            Py_DECREF(obj); /* the buffer holds the array */
        }
        if (failed) {
            release_bufs(b, present, k);
            return NULL;
        }
    }
    Py_ssize_t n = b[RATE].len;
    int shapes = present[TRACE_ROWS] == present[TRACE_INC];
    for (int k = 0; k < RING_VALUES && shapes; k++) {
        if (present[k]) {
            Py_ssize_t columns = SPEC[k].columns ? SPEC[k].columns : 1;
            shapes = b[k].len == columns * n;
        }
    }
    /* the rings: L rows of n poses and flags, the slot one of them */
    Py_ssize_t slot = (Py_ssize_t)s[SLOT];
    double *ring = NULL;
    char *ring_fresh = NULL;
    if (shapes && (present[RING_VALUES] || present[RING_FRESH])) {
        Py_ssize_t rows = n ? b[RING_FRESH].len / n : 0;
        shapes = present[RING_VALUES] && present[RING_FRESH] && n > 0 &&
                 b[RING_FRESH].len == rows * n && b[RING_VALUES].len == 3 * rows * n &&
                 (double)slot == s[SLOT] && slot >= 0 && slot < rows;
        if (shapes) {
            ring = (double *)b[RING_VALUES].data + 3 * n * slot;
            ring_fresh = (char *)b[RING_FRESH].data + n * slot;
        }
    }
    if (!shapes) {
        release_bufs(b, present, N_ARRAYS);
        PyErr_SetString(PyExc_ValueError, "residual_period: shapes differ");
        return NULL;
    }
    double *pose = b[POSE].data, *start = b[START].data, *vel = b[VEL].data;
    double *rate = b[RATE].data, *travel = b[TRAVEL].data;
    double *last_contact = b[LAST_CONTACT].data, *g = b[G].data;
    double *clear = b[CLEAR].data, *acc = b[ACC].data, *acc_abs = b[ACC_ABS].data;
    double *acc_raw = b[ACC_RAW].data, *acc_obs = b[ACC_OBS].data;
    double *acc_pred = b[ACC_PRED].data, *acc_t = b[ACC_T].data;
    double *acc_rot = b[ACC_ROT].data, *acc_rot0 = b[ACC_ROT0].data;
    double *isolating = b[ISOLATING].data;
    int64_t *age = b[AGE].data, *gate = b[GATE].data, *acc_n = b[ACC_N].data;
    char *pending = b[PENDING].data, *detected = b[DETECTED].data;
    const double *seen = b[SEEN].data, *cmd = b[COMMANDS].data;
    const char *fresh = present[FRESH] ? b[FRESH].data : NULL;
    const char *contact = present[CONTACT] ? b[CONTACT].data : NULL;
    const double *accel = b[MOTOR_ACCEL].data, *turn = b[TURN_ACCEL].data;
    const double *brake = b[BRAKE].data;
    int64_t *read = b[READ].data, *cleared = b[CLEARED].data;
    int64_t *alarms = b[ALARMS].data;
    int64_t *trace_rows = present[TRACE_ROWS] ? b[TRACE_ROWS].data : NULL;
    double *trace_inc = present[TRACE_INC] ? b[TRACE_INC].data : NULL;

    double t = s[T], h = s[H], sp = s[SP], sh = s[SH], sigma_h = s[HEADING_NOISE];
    double mu = s[MU], lam = s[LAMBDA], isolation = s[ISOLATION], settle = s[SETTLE];
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
    release_bufs(b, present, N_ARRAYS);
    return Py_BuildValue("(nnnn)", n_read, n_cleared, n_alarms, n_used);
}

static PyMethodDef methods[] = {
    {"residual_period", (PyCFunction)(void (*)(void))residual_period, METH_FASTCALL,
     residual_period_doc},
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
    for (int k = 0; k < N_FIELDS; k++) {
        field_names[k] = PyUnicode_InternFromString(FIELDS[k]);
        if (field_names[k] == NULL) {
            return NULL;
        }
    }
    return PyModule_Create(&module);
}
