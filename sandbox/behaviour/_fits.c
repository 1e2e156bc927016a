/* The crash-or-stop fits of sandbox/behaviour/tracks.py in C.
 *
 * stop_estimates: tracks.stop_estimates calls this where this optional extension is
 * built: every row's sum of squares of the braked-stop model over the grid of speeds
 * and onsets, from prefix sums of t^q and s t^q, as the numpy function computes it
 * (the same formula in the same order). The estimates only choose which rows the
 * fit evaluates: each is trusted within a margin 10^5 times its rounding bound, so
 * any rounding of the same formula chooses rows among which the least sum is the
 * same (tracks.py's module docstring).
 *
 * fits: tracks.stop_fits whole, where the compiled path ``fits`` of sandbox/accel.py
 * is on: the grid of speeds, both models' estimates by prefix sums, the candidate
 * rows, and each candidate's sum of squares (a pairwise summation of the row), within
 * the tolerance of sandbox/accel.py of tracks.fits_numpy.
 */

#include "accel.h"

/* numpy.searchsorted(t, x, side="left"): the first i with t[i] >= x (t sorted). */
static inline Py_ssize_t
search_left(const double *t, Py_ssize_t m, double x)
{
    Py_ssize_t lo = 0, hi = m;
    while (lo < hi) {
        Py_ssize_t mid = lo + (hi - lo) / 2;
        if (t[mid] < x) {
            lo = mid + 1;
        }
        else {
            hi = mid;
        }
    }
    return lo;
}

/* Every braked-stop row's estimate (speed v[row], onset t[j]) into est (speeds, m),
 * from prefix (m + 1, 8): the sums of the first k terms of t^q (q < 5) and of
 * s t^(q - 5). */
static void
stop_rows(const double *t, double s1, double s2, const double *v, Py_ssize_t speeds,
          double brake, const double *prefix, Py_ssize_t m, double *est)
{
#define P(q, k) prefix[(k) * 8 + (q)]
    double a = -0.5 * brake;
    /* In times in order, the end of the braking moves forward with the onset: a
     * pointer finds what the binary search would (both where it is NaN). */
    int in_order = 1;
    for (Py_ssize_t k = 1; k < m; k++) {
        in_order = in_order && t[k - 1] <= t[k];
    }
    for (Py_ssize_t row = 0; row < speeds; row++) {
        double vv = v[row], length = vv / brake;
        Py_ssize_t ahead = 0;
        for (Py_ssize_t j = 0; j < m; j++) {
            double tau = t[j], reach = tau + length;
            Py_ssize_t onset = j + 1, end;
            if (in_order && reach == reach) {
                while (ahead < m && t[ahead] < reach) {
                    ahead++;
                }
                end = ahead;
            }
            else {
                end = search_left(t, m, reach);
            }
            if (end < onset) {
                end = onset;
            }
            double d[8];
            for (int q = 0; q < 8; q++) {
                d[q] = P(q, end) - P(q, onset);
            }
            double r0 = d[0], r1 = d[1], r2 = d[2], r3 = d[3], r4 = d[4];
            double q0 = d[5], q1 = d[6], q2 = d[7];
            double b = vv + brake * tau;
            double c = -0.5 * brake * tau * tau;
            double rest = vv * tau + 0.5 * vv * length;
            double left = (double)(m - end);
            double sum_m = vv * P(1, onset) + (a * r2 + b * r1 + c * r0) + rest * left;
            double sum_mm = vv * vv * P(2, onset) +
                            (a * a * r4 + 2.0 * a * b * r3 + (b * b + 2.0 * a * c) * r2) +
                            (2.0 * b * c * r1 + c * c * r0) + rest * rest * left;
            double sum_sm = vv * P(6, onset) + (a * q2 + b * q1 + c * q0) +
                            rest * (s1 - P(5, end));
            double miss = s1 - sum_m;
            est[row * m + j] = s2 - 2.0 * sum_sm + sum_mm - miss * miss / (double)m;
        }
    }
#undef P
}

PyDoc_STRVAR(stop_estimates_doc,
"stop_estimates(t, s, v, brake, s1, s2, est) -> None\n"
"\n"
"``t``, ``s`` (m,) the track (times from 0, increasing), ``v`` (S,) the speeds,\n"
"``brake`` > 0, ``s1`` and ``s2`` the sums of s and s^2: writes every row's\n"
"estimate to ``est`` (S, m).");

static PyObject *
stop_estimates(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "stop_estimates takes 7 arguments");
        return NULL;
    }
    double brake = PyFloat_AsDouble(args[3]);
    double s1 = PyFloat_AsDouble(args[4]);
    double s2 = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    Rows r[4];
    int got = 0;
    const int at[] = {0, 1, 2, 6};
    for (int k = 0; k < 4; k++) {
        if (get_rows(args[at[k]], &r[k], k == 3) < 0) {
            release(r, got);
            return NULL;
        }
        got++;
    }
    Py_ssize_t m = r[0].len, speeds = r[2].len;
    if (r[1].len != m || r[3].len != speeds * m || m < 1) {
        release(r, got);
        PyErr_SetString(PyExc_ValueError, "stop_estimates: shapes differ");
        return NULL;
    }
    const double *t = r[0].data, *s = r[1].data, *v = r[2].data;
    double *est = r[3].data;
    double *prefix = PyMem_Malloc(sizeof(double) * 8 * (size_t)(m + 1));
    if (prefix == NULL) {
        release(r, got);
        return PyErr_NoMemory();
    }
    /* prefix[k][q]: the sum of the first k terms of t^q (q < 5), s t^(q - 5) */
    for (int q = 0; q < 8; q++) {
        prefix[q] = 0.0;
        for (Py_ssize_t k = 0; k < m; k++) {
            double power = pow(t[k], (double)(q < 5 ? q : q - 5));
            prefix[(k + 1) * 8 + q] = prefix[k * 8 + q] + (q < 5 ? power : power * s[k]);
        }
    }
    stop_rows(t, s1, s2, v, speeds, brake, prefix, m, est);
    PyMem_Free(prefix);
    release(r, got);
    Py_RETURN_NONE;
}

/* The sum of n doubles, pairwise: 8 accumulators up to 128 terms, halves beyond. */
static double
pairwise(const double *a, Py_ssize_t n)
{
    if (n < 8) {
        double res = 0.0;
        for (Py_ssize_t i = 0; i < n; i++) {
            res += a[i];
        }
        return res;
    }
    if (n <= 128) {
        double r[8];
        Py_ssize_t i;
        for (int j = 0; j < 8; j++) {
            r[j] = a[j];
        }
        for (i = 8; i < n - (n % 8); i += 8) {
            for (int j = 0; j < 8; j++) {
                r[j] += a[i + j];
            }
        }
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) {
            res += a[i];
        }
        return res;
    }
    Py_ssize_t n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise(a, n2) + pairwise(a + n2, n - n2);
}

static inline double
row_sum(const double *a, Py_ssize_t n)
{
    return 0.0 + pairwise(a, n);
}

/* tracks.row_ssr of one row of tracks.model_rows (speed vv, onset tau): the
 * residuals less their mean, squared and summed; r is m doubles of scratch. */
static double
row_ssr(const double *t, const double *s, Py_ssize_t m, double vv, double tau,
        double brake, int crash, double *r)
{
    double limit = vv / brake, half = 0.5 * brake;
    for (Py_ssize_t k = 0; k < m; k++) {
        double run = smaller(t[k], tau), model;
        if (crash) {
            model = vv * run;
        }
        else {
            double braking = clamp(t[k] - tau, 0.0, limit);
            model = vv * (run + braking) - half * (braking * braking);
        }
        r[k] = s[k] - model;
    }
    double mean = row_sum(r, m) / (double)m;
    for (Py_ssize_t k = 0; k < m; k++) {
        double d = r[k] - mean;
        r[k] = d * d;
    }
    return row_sum(r, m);
}

/* The least sum of squares of the rows (flat, speed-major) with est - margin of their
 * speed <= the least estimate's + its margin, or of every row where an estimate or
 * margin is not finite (est NULL: untrusted) or more than ``most`` are left
 * (tracks.candidate_rows and tracks.least_row). NaN where a row evaluated is. */
static double
least_candidate(const double *t, const double *s, Py_ssize_t m, const double *v,
                Py_ssize_t speeds, double brake, int crash, const double *est,
                const double *margin, double most, double *r)
{
    Py_ssize_t size = speeds * m, best = 0, count = 0;
    int finite = est != NULL, bad = 0;
    double low = INFINITY;
    for (Py_ssize_t k = 0; k < size && est != NULL; k++) { /* the first least */
        double e = est[k];
        bad |= e - e != 0.0;
        if (e < low) {
            low = e;
            best = k;
        }
    }
    finite &= !bad;
    for (Py_ssize_t a = 0; a < speeds && finite; a++) {
        finite &= margin[a] - margin[a] == 0.0;
    }
    double least = INFINITY, nan = 0.0, ceiling = 0.0;
    int has_nan = 0;
    if (finite) { /* the candidates, evaluated as they are counted */
        ceiling = est[best] + margin[best / m];
        for (Py_ssize_t a = 0; a < speeds; a++) {
            const double *row = est + a * m;
            for (Py_ssize_t j = 0; j < m; j++) {
                if (!(row[j] - margin[a] <= ceiling)) {
                    continue;
                }
                count++;
                double x = row_ssr(t, s, m, v[a], t[j], brake, crash, r);
                has_nan |= x != x;
                nan = x != x ? x : nan;
                least = x < least ? x : least;
            }
        }
    }
    if (!finite || (double)count > most) { /* every row */
        least = INFINITY;
        has_nan = 0;
        for (Py_ssize_t k = 0; k < size; k++) {
            double x = row_ssr(t, s, m, v[k / m], t[k % m], brake, crash, r);
            has_nan |= x != x;
            nan = x != x ? x : nan;
            least = x < least ? x : least;
        }
    }
    return has_nan ? nan : least;
}

PyDoc_STRVAR(fits_doc,
"fits(t, s, brake, speeds, most_rows, margin) -> (crash, stop)\n"
"\n"
"tracks.stop_fits: ``t``, ``s`` (m,) the track, ``brake`` the braking limit,\n"
"``speeds`` the grid's speeds (tracks.SPEEDS), ``most_rows`` the share of the grid's\n"
"rows evaluated from the estimates at most (else every row, tracks.MOST_ROWS),\n"
"``margin`` tracks.MARGIN. The least sums of squares of the crash and the braked\n"
"stop, each as numpy's rows give it; the estimates (where the track is finite, in\n"
"order, and brake > 0) only choose the rows.");

/* The grid's speeds as stop_fits takes them: np.linspace(0, 1.5 max(speed), S) of
 * the speeds over ``lag`` samples, the largest NaN where one is. */
static void
speed_grid(const double *t, const double *s, Py_ssize_t m, double *v, Py_ssize_t speeds)
{
    Py_ssize_t lag = m - 1 < 10 ? m - 1 : 10;
    double fastest = 0.0;
    int has_nan = 0;
    for (Py_ssize_t k = 0; k + lag < m; k++) {
        double speed = fabs(s[k + lag] - s[k]) / larger(t[k + lag] - t[k], 1e-9);
        has_nan |= speed != speed;
        fastest = (k == 0 || speed > fastest) ? speed : fastest;
    }
    double stop = 1.5 * (has_nan ? NAN : fastest);
    /* linspace: delta / div, each k times it (k / div times delta where that is
     * 0), plus the start 0.0; the last is the stop itself */
    double div = (double)(speeds - 1), step = (stop - 0.0) / div;
    for (Py_ssize_t k = 0; k < speeds; k++) {
        double y = (double)k;
        y = step == 0 ? y / div * (stop - 0.0) : y * step;
        v[k] = y + 0.0;
    }
    v[speeds - 1] = stop;
}

static PyObject *
fits(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "fits takes 6 arguments");
        return NULL;
    }
    double brake = PyFloat_AsDouble(args[2]);
    Py_ssize_t speeds = PyLong_AsSsize_t(args[3]);
    double most_rows = PyFloat_AsDouble(args[4]);
    double factor = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    Rows r[2];
    if (get_all_rows(args, r, 2, 2) < 0) {
        return NULL;
    }
    int got = 2;
    Py_ssize_t m = r[0].len;
    if (r[1].len != m || m < 2 || speeds < 2) {
        release(r, got);
        PyErr_SetString(PyExc_ValueError, "fits: shapes differ, or too few samples");
        return NULL;
    }
    const double *s = r[1].data;
    /* scratch: t (m), v (speeds), est (speeds, m), margin (speeds), prefix
     * (8, m + 1), rows (3 m) */
    size_t need = (size_t)(m + speeds + speeds * m + speeds + 8 * (m + 1) + 3 * m);
    double *work = PyMem_Malloc(sizeof(double) * need);
    if (work == NULL) {
        release(r, got);
        return PyErr_NoMemory();
    }
    double *t = work, *v = t + m, *est = v + speeds, *margin = est + speeds * m;
    double *prefix = margin + speeds, *row = prefix + 8 * (m + 1);
    for (Py_ssize_t k = 0; k < m; k++) { /* the times from the first */
        t[k] = r[0].data[k] - r[0].data[0];
    }
    speed_grid(t, s, m, v, speeds);
    double most = most_rows * (double)speeds * (double)m;
    /* whether the estimates may be trusted, as stop_fits decides */
    int trusted = brake > 0.0;
    double span = 0.0, s1 = 0.0, s2 = 0.0;
    for (Py_ssize_t k = 0; k < m; k++) {
        trusted = trusted && isfinite(t[k]) && isfinite(s[k]);
        trusted = trusted && (k == 0 || t[k] - t[k - 1] >= 0.0);
        span = fabs(t[k]) > span ? fabs(t[k]) : span;
        s1 += s[k];
        s2 += s[k] * s[k];
    }
    if (trusted) {
        /* prefix[k][q]: the first k terms' sums of t^q (q < 5), s t^(q - 5) */
        for (int q = 0; q < 8; q++) {
            prefix[q] = 0.0;
        }
        for (Py_ssize_t k = 0; k < m; k++) {
            double tk = t[k], t2 = tk * tk;
            double term[8] = {1.0, tk, t2, t2 * tk, t2 * t2, s[k], s[k] * tk, s[k] * t2};
            for (int q = 0; q < 8; q++) {
                prefix[(k + 1) * 8 + q] = prefix[k * 8 + q] + term[q];
            }
        }
    }
    double out[2];
    for (int crash = 1; crash >= 0; crash--) {
        if (trusted && crash) {
            /* tracks.crash_estimates with g = min(t, t_j) summed by the prefixes */
#define P(q, k) prefix[(k) * 8 + (q)]
            /* each onset's sums of g, g^2 and s g (the row of scratch, 3 m) */
            double *g1 = row, *g2 = row + m, *sg = row + 2 * m;
            for (Py_ssize_t j = 0; j < m; j++) {
                double tj = t[j], after = (double)(m - 1 - j);
                g1[j] = P(1, j + 1) + after * tj;
                g2[j] = P(2, j + 1) + after * tj * tj;
                sg[j] = P(6, j + 1) + tj * (s1 - P(5, j + 1));
            }
            double inverse = 1.0 / (double)m;
            for (Py_ssize_t a = 0; a < speeds; a++) {
                double vv = v[a], reach = vv * span, *e = est + a * m;
                margin[a] = factor * (s2 + (double)m * reach * reach);
                for (Py_ssize_t j = 0; j < m; j++) {
                    double miss = s1 - vv * g1[j];
                    e[j] = s2 - 2.0 * vv * sg[j] + vv * vv * g2[j] -
                           miss * miss * inverse;
                }
            }
#undef P
        }
        else if (trusted) {
            stop_rows(t, s1, s2, v, speeds, brake, prefix, m, est);
            for (Py_ssize_t a = 0; a < speeds; a++) {
                double vv = v[a];
                double reach = 2.0 * brake * span * span + vv * (2.0 * span + vv / brake);
                margin[a] = factor * (s2 + (double)m * reach * reach);
            }
        }
        out[crash ? 0 : 1] = least_candidate(t, s, m, v, speeds, brake, crash,
                                             trusted ? est : NULL, margin, most, row);
    }
    PyMem_Free(work);
    release(r, got);
    return Py_BuildValue("(dd)", out[0], out[1]);
}

static PyMethodDef methods[] = {
    {"stop_estimates", (PyCFunction)(void (*)(void))stop_estimates, METH_FASTCALL,
     stop_estimates_doc},
    {"fits", (PyCFunction)(void (*)(void))fits, METH_FASTCALL, fits_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_fits",
    "The braked-stop fits' estimates in C (see sandbox/behaviour/tracks.py).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__fits(void)
{
    return PyModule_Create(&module);
}
