/* The velocity barrier's step of the CBF filter in one C call, and its counters.
 *
 * sandbox/behaviour/safety/filter_kernel.py calls velocity_step where this optional
 * extension is built (the compiled path ``filter`` of sandbox/accel.py); it does, for the rows of every world at
 * once, what cbf.filter_commands does with numpy for ``barrier: velocity`` without a
 * priority: the boxes of the inputs (_box) and each vehicle's reach, the pairs of
 * the neighbour search's candidates closer than the range, the exact pruning of the
 * pairs that cannot bind, both directions of the rest (braking.pair_geometry) and
 * their half-planes (cbf.barrier_rows), the obstacles' rows (made by numpy, handed
 * in), the rotation into z = (v1, l v2) and the prune by reach, each vehicle's
 * rows ordered by b (ties in the order they were made) and cut at max_rows, the exact projection of its
 * bounded problem (qp_project.h), the right-hand rule's second projection
 * (right_hand.pass_right), and the commands written back where they changed. A
 * vehicle whose problem, or whose turned problem, has no point (which needs
 * qp.min_violation, LAPACK's) is handed back to numpy with its problem.
 *
 * world_counts does the reductions of accounting.account_worlds, and project the
 * exact projections of qp.project over many problems (the compiled path ``qp``).
 *
 * The C library's sin, cos and hypot; the numbers agree with the numpy step within
 * the tolerance of sandbox/accel.py.
 */

#include "accel.h"
#include "qp_project.h"

/* One half-plane a . w <= b of vehicle ``veh`` (a turned into z once kept). */
typedef struct {
    Py_ssize_t veh;
    double a0, a1, b;
} Row;

/* The arguments of velocity_step, by name (accel.h). */
#define VELOCITY_STEP(X)                                                           \
    X(pos, FLOATS, 0)                                                              \
    X(theta, FLOATS, 0)                                                            \
    X(vel, FLOATS, 0)                                                              \
    X(v1, FLOATS, 0)                                                               \
    X(v2, FLOATS, 0)                                                               \
    X(diameter, FLOATS, 0)                                                         \
    X(v1_prev, FLOATS, OR_NONE)                                                    \
    X(v2_prev, FLOATS, OR_NONE)                                                    \
    X(known_failed, BYTES, OR_NONE)                                                \
    X(commanded, BYTES, OR_NONE)                                                   \
    X(seen, FLOATS, OR_NONE)                                                       \
    X(v1_max, FLOATS, 0)                                                           \
    X(lateral, FLOATS, 0)                                                          \
    X(accel, FLOATS, 0)                                                            \
    X(cand_i, INTPS, 0)                                                            \
    X(cand_j, INTPS, 0)                                                            \
    X(obs_rows, INTPS, OR_NONE)                                                    \
    X(obs_signed, FLOATS, OR_NONE)                                                 \
    X(obs_away, FLOATS, OR_NONE)                                                   \
    X(gamma, NUMBER, 0)                                                            \
    X(look, NUMBER, 0)                                                             \
    X(margin, NUMBER, 0)                                                           \
    X(radius, NUMBER, 0)                                                           \
    X(dt, NUMBER, 0)                                                               \
    X(pass_right, NUMBER, 0)                                                       \
    X(tolerance, NUMBER, 0)                                                        \
    X(min_dist, NUMBER, 0)                                                         \
    X(min_speed, NUMBER, 0)                                                        \
    X(stall_start, NUMBER, 0)                                                      \
    X(stall_full, NUMBER, 0)                                                       \
    X(stall_speed, NUMBER, 0)                                                      \
    X(reverse, INTEGER, 0)                                                         \
    X(speed_only, INTEGER, 0)                                                      \
    X(broadcast, INTEGER, 0)                                                       \
    X(max_rows, INTEGER, 0)                                                        \
    X(v1_out, FLOATS, WRITTEN)                                                     \
    X(v2_out, FLOATS, WRITTEN)                                                     \
    X(active, BYTES, WRITTEN)                                                      \
    X(slack, FLOATS, WRITTEN)                                                      \
    X(by_vehicle, FLOATS, WRITTEN)                                                 \
    X(pending, INTPS, WRITTEN)                                                     \
    X(pending_m, INTPS, WRITTEN)                                                   \
    X(pending_mat, FLOATS, WRITTEN)                                                \
    X(pending_off, FLOATS, WRITTEN)
NAMED(velocity_step, VELOCITY_STEP)

PyDoc_STRVAR(velocity_step_doc,
"velocity_step(*, pos, theta, vel, v1, v2, diameter, v1_prev, v2_prev,\n"
"    known_failed, commanded, seen, v1_max, lateral, accel, cand_i, cand_j,\n"
"    obs_rows, obs_signed, obs_away, gamma, look, margin, radius, dt, pass_right,\n"
"    tolerance, min_dist, min_speed, stall_start, stall_full, stall_speed,\n"
"    reverse, speed_only, broadcast, max_rows, v1_out, v2_out, active, slack,\n"
"    by_vehicle, pending, pending_m, pending_mat, pending_off)\n"
"    -> (rows, least, n_pending)\n"
"\n"
"The velocity barrier's filtered commands of n vehicles (see filter_kernel.py):\n"
"``v1_out``, ``v2_out``, ``active``, ``slack`` and ``by_vehicle`` written; ``rows``\n"
"is -1 where no vehicle is filtered. The vehicles whose problems have no point\n"
"are listed in ``pending`` (their row count in ``pending_m``, their problems\n"
"(4 + max_rows, 2) and (4 + max_rows,) in ``pending_mat`` and ``pending_off``), their\n"
"commands left as given, for numpy to solve. ``v1_prev``, ``v2_prev``,\n"
"``known_failed``, ``commanded``, ``seen`` and the obstacles' rows may be None.");

static PyObject *
velocity_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
              PyObject *kwnames)
{
    velocity_step_args a;
    if (parse_named(&velocity_step_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    char *scratch = NULL;
    const Py_ssize_t max_rows = a.max_rows.n, width = 4 + max_rows;
    const Py_ssize_t N = a.theta.len, nc = a.cand_i.len, no = a.obs_rows.len;
    if (max_rows < 1) {
        PyErr_SetString(PyExc_ValueError, "velocity_step: max_rows < 1");
        goto done;
    }
    if (a.pos.len != 2 * N || a.vel.len != 2 * N || a.v1.len != N || a.v2.len != N ||
        a.diameter.len != N || (a.v1_prev.f && a.v1_prev.len != N) ||
        (a.v2_prev.f && a.v2_prev.len != N) ||
        (a.known_failed.b && a.known_failed.len != N) ||
        (a.commanded.b && a.commanded.len != N) || (a.seen.f && a.seen.len != 3 * N) ||
        a.v1_max.len != N || a.lateral.len != N || a.accel.len != N ||
        a.cand_j.len != nc || (a.obs_signed.f && a.obs_signed.len != no) ||
        (a.obs_away.f && a.obs_away.len != 2 * no) || a.v1_out.len != N ||
        a.v2_out.len != N || a.active.len != N || a.slack.len != N ||
        a.by_vehicle.len != N || a.pending.len != N || a.pending_m.len != N ||
        a.pending_mat.len != 2 * N * width || a.pending_off.len != N * width) {
        PyErr_SetString(PyExc_ValueError, "velocity_step: shapes differ");
        goto done;
    }
    const double *pos = a.pos.f, *theta = a.theta.f, *vel = a.vel.f, *v1 = a.v1.f;
    const double *v2 = a.v2.f, *diam = a.diameter.f, *v1p = a.v1_prev.f;
    const double *v2p = a.v2_prev.f, *seen = a.seen.f, *v1_max = a.v1_max.f;
    const double *lateral = a.lateral.f, *accel = a.accel.f;
    const double *signed_d = a.obs_signed.f, *away = a.obs_away.f;
    const unsigned char *failed = a.known_failed.b, *commanded = a.commanded.b;
    const Py_ssize_t *ci = a.cand_i.i, *cj = a.cand_j.i, *orow = a.obs_rows.i;
    double *v1_out = a.v1_out.f, *v2_out = a.v2_out.f, *slack = a.slack.f;
    double *by = a.by_vehicle.f, *pmat = a.pending_mat.f, *poff = a.pending_off.f;
    unsigned char *active = a.active.b;
    Py_ssize_t *pend = a.pending.i, *pend_m = a.pending_m.i;
    if ((v1p == NULL) != (v2p == NULL) ||
        (orow != NULL && (signed_d == NULL || away == NULL))) {
        PyErr_SetString(PyExc_ValueError, "velocity_step: arrays missing");
        goto done;
    }
    for (Py_ssize_t k = 0; k < nc; k++) {
        if (ci[k] < 0 || ci[k] >= N || cj[k] < 0 || cj[k] >= N) {
            PyErr_SetString(PyExc_IndexError, "velocity_step: a pair out of range");
            goto done;
        }
    }
    for (Py_ssize_t k = 0; k < no; k++) {
        if (orow[k] < 0 || orow[k] >= N) {
            PyErr_SetString(PyExc_IndexError, "velocity_step: a row out of range");
            goto done;
        }
    }
    const double gamma = a.gamma.x, look = a.look.x, margin = a.margin.x;
    const double radius = a.radius.x, dt = a.dt.x, angle = a.pass_right.x;
    const double tol = a.tolerance.x, min_dist = a.min_dist.x;
    const double min_speed = a.min_speed.x, start = a.stall_start.x;
    const double full = a.stall_full.x, slow = a.stall_speed.x;
    const int reverse = a.reverse.n != 0, speed_only = a.speed_only.n != 0;
    const int broadcast = a.broadcast.n != 0, prev = v1p != NULL;

    /* One block for the call: per vehicle 17 doubles and 3 counts, per candidate
     * pair its place, distance and barrier, rows for both directions of every pair
     * and every obstacle (and their order), per vehicle a flag. */
    Py_ssize_t cap = 2 * nc + no;
    size_t doubles = 17 * (size_t)N + 2 * (size_t)nc;
    size_t counts = 3 * (size_t)N + (size_t)nc + (size_t)cap;
    size_t bytes = sizeof(double) * doubles + sizeof(Py_ssize_t) * counts +
                   sizeof(Row) * (size_t)cap + (size_t)N + 1;
    scratch = PyMem_Malloc(bytes);
    if (scratch == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    double *cos_t = (double *)scratch, *sin_t = cos_t + N, *p = sin_t + N;
    double *ps = p + 2 * N, *cs = ps + 2 * N, *w = cs + 2 * N, *z0 = w + 2 * N;
    double *lo1 = z0 + 2 * N, *hi1 = lo1 + N, *lo2 = hi1 + N, *hi2 = lo2 + N;
    double *reach = hi2 + N, *pair_dist = reach + N, *pair_h = pair_dist + nc;
    Row *rows = (Row *)(pair_h + nc);
    Py_ssize_t *count = (Py_ssize_t *)(rows + cap), *first = count + N;
    Py_ssize_t *fill = first + N, *near = fill + N, *order = near + nc;
    unsigned char *filt = (unsigned char *)(order + cap);

    /* The vehicles: look_ahead_points, w_hat, the filtered ones, z0, _box, reach. */
    Py_ssize_t who = 0;
    for (Py_ssize_t v = 0; v < N; v++) {
        double c = cos(theta[v]), s = sin(theta[v]);
        cos_t[v] = c;
        sin_t[v] = s;
        p[2 * v] = pos[2 * v] + look * c;
        p[2 * v + 1] = pos[2 * v + 1] + look * s;
        if (seen != NULL) {
            const double *q = seen + 3 * v;
            cs[2 * v] = q[0];
            cs[2 * v + 1] = q[1];
            ps[2 * v] = q[0] + look * cos(q[2]);
            ps[2 * v + 1] = q[1] + look * sin(q[2]);
        }
        else {
            cs[2 * v] = pos[2 * v];
            cs[2 * v + 1] = pos[2 * v + 1];
            ps[2 * v] = p[2 * v];
            ps[2 * v + 1] = p[2 * v + 1];
        }
        if (prev) { /* heading v1^ + (-(l v2^ sin), l v2^ cos) */
            double t = look * v2p[v];
            w[2 * v] = c * v1p[v] + -(t * s);
            w[2 * v + 1] = s * v1p[v] + t * c;
        }
        filt[v] = !(failed != NULL && failed[v]) &&
                  !(commanded != NULL && commanded[v]);
        who += filt[v];
        z0[2 * v] = v1[v];
        z0[2 * v + 1] = look * v2[v];
        double l1 = 0.0, h1 = 0.0, l2 = 0.0, h2 = 0.0;
        if (filt[v]) {
            l1 = reverse ? -v1_max[v] : 0.0;
            h1 = v1_max[v];
            if (prev) {
                double step = accel[v] * dt;
                l1 = larger(l1, v1p[v] - step);
                h1 = smaller(h1, v1p[v] + step);
                l1 = smaller(l1, h1);
            }
            if (speed_only) {
                l2 = h2 = z0[2 * v + 1];
            }
            else {
                l2 = -lateral[v];
                h2 = lateral[v];
            }
        }
        lo1[v] = l1;
        hi1[v] = h1;
        lo2[v] = l2;
        hi2[v] = h2;
        if (filt[v] && seen == NULL) { /* the pruning's reach (of filtered ones) */
            double zh0 = prev ? v1p[v] : 0.0, zh1 = prev ? look * v2p[v] : 0.0;
            double r = hypot(larger(fabs(l1 - zh0), fabs(h1 - zh0)),
                             larger(fabs(l2 - zh1), fabs(h2 - zh1)));
            reach[v] = r * (1.0 + 1e-9) + 1e-9;
        }
        if (by != NULL) {
            by[v] = INFINITY;
        }
        v1_out[v] = v1[v];
        v2_out[v] = v2[v];
        active[v] = 0;
        slack[v] = 0.0;
    }
    if (who == 0) {
        result = Py_BuildValue("(ndn)", (Py_ssize_t)-1, INFINITY, (Py_ssize_t)0);
        goto done;
    }
    double least = INFINITY;

    /* The neighbour search's filter on the seen look-ahead points, then (without
     * sensing) the pairs that cannot bind dropped. */
    Py_ssize_t kept = 0;
    double r2 = radius * radius;
    for (Py_ssize_t k = 0; k < nc; k++) {
        Py_ssize_t i = ci[k], j = cj[k];
        double x = ps[2 * i] - ps[2 * j], y = ps[2 * i + 1] - ps[2 * j + 1];
        if (x * x + y * y < r2) {
            near[kept++] = k;
        }
    }
    if (kept && seen == NULL) {
        double pair = INFINITY;
        Py_ssize_t out = 0;
        for (Py_ssize_t q = 0; q < kept; q++) {
            Py_ssize_t k = near[q], i = ci[k], j = cj[k];
            double x = p[2 * i] - p[2 * j], y = p[2 * i + 1] - p[2 * j + 1];
            double dist = larger(hypot(x, y), min_dist);
            double big_d = 0.5 * (diam[i] + diam[j]) + 2.0 * look + margin;
            double hh = dist * dist - big_d * big_d;
            int both = filt[i] && filt[j];
            if (filt[i] || filt[j]) {
                pair = smaller(pair, hh);
                if (by != NULL) {
                    by[i] = smaller(by[i], hh);
                }
            }
            double base = 0.25 * gamma * hh / dist, slack_i = base, slack_j = base;
            if (prev) {
                double ux = x / dist, uy = y / dist;
                double along_i = ux * w[2 * i] + uy * w[2 * i + 1];
                double along_j = ux * w[2 * j] + uy * w[2 * j + 1];
                if (broadcast) { /* a quarter budget less closing, the same for both */
                    slack_i = slack_j = base + 0.5 * (along_i - along_j);
                }
                else {
                    slack_i = base + along_i;
                    slack_j = base - along_j;
                }
            }
            if (!both || slack_i < reach[i] || slack_j < reach[j]) {
                pair_dist[out] = dist; /* the same for both directions' rows */
                pair_h[out] = hh;
                near[out++] = k;
            }
        }
        least = smaller(least, pair);
        kept = out;
    }

    /* Both directions of each pair (pair_geometry), then the obstacles' rows. */
    Py_ssize_t made = 0;
    double made_least = INFINITY;
    for (int side = 0; side < 2; side++) {
        for (Py_ssize_t q = 0; q < kept; q++) {
            Py_ssize_t k = near[q];
            Py_ssize_t me = side ? cj[k] : ci[k], other = side ? ci[k] : cj[k];
            if (!filt[me]) {
                continue;
            }
            int coop = filt[other];
            const double *target = coop ? ps + 2 * other : cs + 2 * other;
            double x = p[2 * me] - target[0], y = p[2 * me + 1] - target[1];
            double dist, hh;
            if (coop && seen == NULL) { /* the pruning's: rel is +-(p_i - p_j) */
                dist = pair_dist[q];
                hh = pair_h[q];
            }
            else {
                dist = larger(hypot(x, y), min_dist);
                double big_d = 0.5 * (diam[me] + diam[other]) +
                               (coop ? 2.0 * look : look) + margin;
                hh = dist * dist - big_d * big_d;
            }
            made_least = smaller(made_least, hh);
            if (by != NULL) {
                by[me] = smaller(by[me], hh);
            }
            double share = 0.0;
            if (prev && broadcast) {
                double s0 = w[2 * me] + w[2 * other];
                double s1 = w[2 * me + 1] + w[2 * other + 1];
                share = 0.0 + x * s0 + y * s1;
            }
            double moving = 0.0 + x * vel[2 * other] + y * vel[2 * other + 1];
            double rhs = coop ? -0.5 * gamma * hh + share : -gamma * hh + 2.0 * moving;
            Row *r = rows + made++;
            r->veh = me;
            r->a0 = -x / dist;
            r->a1 = -y / dist;
            r->b = -rhs / (2.0 * dist);
        }
    }
    least = smaller(least, made_least);
    double wall = INFINITY;
    for (Py_ssize_t k = 0; k < no; k++) {
        Py_ssize_t v = orow[k];
        double clearance = 0.5 * diam[v] + look + margin;
        double g = signed_d[k] - clearance;
        wall = smaller(wall, g);
        if (by != NULL) {
            by[v] = smaller(by[v], g);
        }
        Row *r = rows + made++;
        r->veh = v;
        r->a0 = -away[2 * k];
        r->a1 = -away[2 * k + 1];
        r->b = gamma * (signed_d[k] - clearance);
    }
    least = smaller(least, wall);

    /* In z = (v1, l v2): a . w = (R^T a) . z; the rows no input within the bounds
     * can violate dropped, the rest counted per vehicle in their order. */
    for (Py_ssize_t v = 0; v < N; v++) {
        count[v] = 0;
    }
    Py_ssize_t live = 0;
    for (Py_ssize_t k = 0; k < made; k++) {
        Row *r = rows + k;
        Py_ssize_t v = r->veh;
        double c = cos_t[v], s = sin_t[v];
        double a0 = c * r->a0 + s * r->a1, a1 = -s * r->a0 + c * r->a1;
        double most = larger(a0 * lo1[v], a0 * hi1[v]) +
                      larger(a1 * lo2[v], a1 * hi2[v]);
        if (most > r->b - tol) {
            r->a0 = a0;
            r->a1 = a1;
            rows[live++] = *r;
            count[v]++;
        }
    }
    /* By vehicle (a stable bucket), then by b (a stable insertion sort: ties keep
     * the order the rows were made in). */
    Py_ssize_t total = 0;
    for (Py_ssize_t v = 0; v < N; v++) {
        first[v] = total;
        fill[v] = total;
        total += count[v];
    }
    for (Py_ssize_t k = 0; k < live; k++) {
        order[fill[rows[k].veh]++] = k;
    }
    Py_ssize_t kept_rows = 0;
    for (Py_ssize_t v = 0; v < N; v++) {
        Py_ssize_t *o = order + first[v];
        for (Py_ssize_t a = 1; a < count[v]; a++) {
            Py_ssize_t cur = o[a], b = a;
            while (b > 0 && rows[cur].b < rows[o[b - 1]].b) {
                o[b] = o[b - 1];
                b--;
            }
            o[b] = cur;
        }
        if (count[v] > max_rows) {
            count[v] = max_rows;
        }
        kept_rows += count[v];
    }

    /* Each filtered vehicle's problem: the bounds only (a clip), or the four bounds
     * and its rows (qp.bounded_problems), projected exactly, then the right-hand
     * rule's turn and second projection. */
    Py_ssize_t pending = 0;
    double mat[2 * (4 + 16)], off[4 + 16];
    for (Py_ssize_t v = 0; v < N; v++) {
        if (!filt[v]) {
            continue;
        }
        double x0 = z0[2 * v], y0 = z0[2 * v + 1], z[2];
        Py_ssize_t m = count[v];
        if (m == 0) {
            z[0] = clamp(x0, lo1[v], hi1[v]);
            z[1] = clamp(y0, lo2[v], hi2[v]);
        }
        else {
            double *a = m <= 16 ? mat : pmat + 2 * width * pending;
            double *b = m <= 16 ? off : poff + width * pending;
            for (int q = 0; q < 8; q++) {
                a[q] = 0.0;
            }
            a[0] = 1.0;
            b[0] = hi1[v];
            a[2] = -1.0;
            b[1] = -lo1[v];
            a[5] = 1.0;
            b[2] = hi2[v];
            a[7] = -1.0;
            b[3] = -lo2[v];
            const Py_ssize_t *o = order + first[v];
            for (Py_ssize_t q = 0; q < m; q++) {
                a[2 * (4 + q)] = rows[o[q]].a0;
                a[2 * (4 + q) + 1] = rows[o[q]].a1;
                b[4 + q] = rows[o[q]].b;
            }
            int ok = project_one(a, b, 4 + m, x0, y0, tol, z);
            if (ok && angle > 0 && !speed_only) {
                double nominal = hypot(x0, y0);
                double kept_speed =
                    z[0] == x0 && z[1] == y0 ? nominal : hypot(z[0], z[1]);
                double cut = 1.0 - kept_speed / larger(nominal, min_speed);
                double x =
                    clamp((cut - (1.0 - start)) / (start - full), 0.0, 1.0);
                double ramp = x * x * (3.0 - 2.0 * x);
                double turn = angle * ramp * smaller(nominal / slow, 1.0);
                if (turn > 0) { /* clockwise by the turn */
                    double c = cos(turn), s = sin(turn);
                    ok = project_one(a, b, 4 + m, c * x0 + s * y0, c * y0 - s * x0,
                                     tol, z);
                }
            }
            if (!ok) { /* no point: qp.min_violation, by the caller */
                if (a != pmat + 2 * width * pending) {
                    memcpy(pmat + 2 * width * pending, a, sizeof(double) * 2 * (4 + m));
                    memcpy(poff + width * pending, b, sizeof(double) * (4 + m));
                }
                pend[pending] = v;
                pend_m[pending] = m;
                pending++;
                continue;
            }
        }
        if (z[0] != x0 || z[1] != y0) { /* changed: the commands written back */
            v1_out[v] = z[0];
            if (!speed_only) {
                v2_out[v] = z[1] / look;
            }
            active[v] = 1;
        }
    }
    result = Py_BuildValue("(ndn)", kept_rows, least, pending);
done:
    PyMem_Free(scratch);
    release_named(&velocity_step_signature, (Arg *)&a);
    return result;
}

/* The arguments of world_counts, by name (accel.h). */
#define WORLD_COUNTS(X)                                                            \
    X(worlds, INTEGER, 0)                                                          \
    X(active, BYTES, 0)                                                            \
    X(slack, FLOATS, 0)                                                            \
    X(by_vehicle, FLOATS, OR_NONE)                                                 \
    X(fallback, BYTES, OR_NONE)                                                    \
    X(max_slack, FLOATS, WRITTEN)                                                  \
    X(min_barrier, FLOATS, WRITTEN)                                                \
    X(started, INTEGER, 0)                                                         \
    X(out_active, INTPS, WRITTEN)                                                  \
    X(out_bad, INTPS, WRITTEN)                                                     \
    X(out_worst, FLOATS, WRITTEN)                                                  \
    X(out_least, FLOATS, WRITTEN)                                                  \
    X(out_fallen, INTPS, WRITTEN)                                                  \
    X(out_changes, INTPS, WRITTEN)                                                 \
    X(touched, INTPS, WRITTEN)                                                     \
    X(tolerance, NUMBER, 0)
NAMED(world_counts, WORLD_COUNTS)

PyDoc_STRVAR(world_counts_doc,
"world_counts(*, worlds, active, slack, by_vehicle, fallback, max_slack,\n"
"    min_barrier, started, out_active, out_bad, out_worst, out_least, out_fallen,\n"
"    out_changes, touched, tolerance) -> count\n"
"\n"
"accounting.account_worlds' reductions of one step over ``worlds`` worlds of n rows:\n"
"each world's active count, count of slack above ``tolerance``, largest slack, least\n"
"barrier (inf without ``by_vehicle``) and fallback count (0 without ``fallback``);\n"
"``max_slack`` and ``min_barrier`` raised and lowered, and where (``out_changes``:\n"
"1 raised, 2 lowered). The worlds whose counters change (every world unless\n"
"``started``) are listed in ``touched``, their count returned.");

static PyObject *
world_counts(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
             PyObject *kwnames)
{
    world_counts_args a;
    if (parse_named(&world_counts_signature, args, nargs, kwnames, (Arg *)&a) < 0) {
        return NULL;
    }
    PyObject *result = NULL;
    const Py_ssize_t K = a.worlds.n, N = a.active.len;
    const int started = a.started.n != 0;
    const double tol = a.tolerance.x;
    if (K <= 0 || N % K != 0 || N == 0) {
        PyErr_SetString(PyExc_ValueError, "world_counts: rows not K n, n > 0");
        goto done;
    }
    if (a.slack.len != N || (a.by_vehicle.f && a.by_vehicle.len != N) ||
        (a.fallback.b && a.fallback.len != N) || a.max_slack.len != K ||
        a.min_barrier.len != K || a.out_active.len != K || a.out_bad.len != K ||
        a.out_worst.len != K || a.out_least.len != K || a.out_fallen.len != K ||
        a.out_changes.len != K || a.touched.len != K) {
        PyErr_SetString(PyExc_ValueError, "world_counts: shapes differ");
        goto done;
    }
    const unsigned char *active = a.active.b, *fallback = a.fallback.b;
    const double *slack = a.slack.f, *by = a.by_vehicle.f;
    double *max_slack = a.max_slack.f, *min_barrier = a.min_barrier.f;
    double *worst = a.out_worst.f, *least = a.out_least.f;
    Py_ssize_t *n_active = a.out_active.i, *n_bad = a.out_bad.i;
    Py_ssize_t *n_fallen = a.out_fallen.i, *changes = a.out_changes.i;
    Py_ssize_t *touched = a.touched.i;
    Py_ssize_t n = N / K, out = 0;
    for (Py_ssize_t w = 0; w < K; w++) {
        Py_ssize_t on = 0, bad = 0, fallen = 0;
        double big = slack[w * n], small = by != NULL ? by[w * n] : INFINITY;
        for (Py_ssize_t k = w * n; k < (w + 1) * n; k++) {
            on += active[k] != 0;
            bad += slack[k] > tol;
            if (fallback != NULL) {
                fallen += fallback[k] != 0;
            }
            big = larger(slack[k], big);
            if (by != NULL) {
                small = smaller(by[k], small);
            }
        }
        n_active[w] = on;
        n_bad[w] = bad;
        n_fallen[w] = fallen;
        worst[w] = big;
        least[w] = small;
        int raised = big > max_slack[w];
        int fell = isfinite(small) && small < min_barrier[w];
        changes[w] = raised | (fell << 1);
        if (!started || on > 0 || bad > 0 || raised || fell || fallen > 0) {
            touched[out++] = w;
        }
        if (raised) {
            max_slack[w] = big;
        }
        if (fell) {
            min_barrier[w] = small;
        }
    }
    result = PyLong_FromSsize_t(out);
done:
    release_named(&world_counts_signature, (Arg *)&a);
    return result;
}

PyDoc_STRVAR(project_doc,
"project(z0, a, b, tol, z, feasible) -> None\n"
"\n"
"``z0`` (n, 2), ``a`` (n, m, 2), ``b`` (n, m) float64; writes the nearest point of\n"
"each polygon to ``z`` (n, 2) (``z0`` where it is empty) and ``feasible`` (n,) bool.");

static PyObject *
project(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "project takes 6 arguments");
        return NULL;
    }
    double tol = PyFloat_AsDouble(args[3]);
    if (tol == -1.0 && PyErr_Occurred()) {
        return NULL;
    }
    Rows r[4];
    Py_buffer ok;
    int got = 0, got_ok = 0;
    PyObject *result = NULL;
    const int at[] = {0, 1, 2, 4};
    for (int k = 0; k < 4; k++) {
        if (get_rows(args[at[k]], &r[k], k == 3) < 0) goto done;
        got++;
    }
    if (PyObject_GetBuffer(args[5], &ok, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE) < 0)
        goto done;
    got_ok = 1;
    Py_ssize_t n = r[0].len / 2;
    Py_ssize_t m = n ? r[2].len / n : 0;
    if (r[0].len != 2 * n || r[2].len != n * m || r[1].len != 2 * n * m ||
        r[3].len != 2 * n || ok.len != n || ok.itemsize != 1) {
        PyErr_SetString(PyExc_ValueError, "project: shapes differ");
        goto done;
    }
    const double *z0 = r[0].data, *A = r[1].data, *B = r[2].data;
    double *z = r[3].data;
    unsigned char *feasible = ok.buf;
    for (Py_ssize_t k = 0; k < n; k++) {
        feasible[k] = (unsigned char)project_one(A + 2 * m * k, B + m * k, m, z0[2 * k],
                                                 z0[2 * k + 1], tol, z + 2 * k);
    }
    result = Py_None;
    Py_INCREF(result);
done:
    release(r, got);
    if (got_ok) {
        PyBuffer_Release(&ok);
    }
    return result;
}

static PyMethodDef methods[] = {
    {"velocity_step", (PyCFunction)(void (*)(void))velocity_step,
     METH_FASTCALL | METH_KEYWORDS, velocity_step_doc},
    {"world_counts", (PyCFunction)(void (*)(void))world_counts,
     METH_FASTCALL | METH_KEYWORDS, world_counts_doc},
    {"project", (PyCFunction)(void (*)(void))project, METH_FASTCALL, project_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_filter",
    "The CBF filter's velocity barrier, its counters and its projections in C.",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__filter(void)
{
    return PyModule_Create(&module);
}
