/* The exact projection of one problem of sandbox/behaviour/safety/qp.py (project).
 *
 * Included by _filter.c: qp.project over many problems (project) and the velocity
 * barrier's whole step. For one problem it does what qp.project_numpy does: z0
 * itself if it keeps every half-plane (within the tolerance); else every candidate
 * (the projections of z0 on the edge lines, then the vertices of each pair of lines
 * i < j), the feasible ones kept and the nearest returned (the first on a tie).
 */

#ifndef SANDBOX_QP_PROJECT_H
#define SANDBOX_QP_PROJECT_H

#include <math.h>

/* qp.SINGULAR: below this |determinant| two lines are taken as parallel. */
#define SINGULAR 1e-12

/* The nearest point of {z : a_q . z <= b_q, q < m} to (x0, y0), written to z[0..1]
 * (z0 itself where the polygon is empty); returns whether it had a point. */
static inline int
project_one(const double *a, const double *b, Py_ssize_t m, double x0, double y0,
            double tol, double *z)
{
    z[0] = x0;
    z[1] = y0;
    for (Py_ssize_t q = 0; q < m; q++) {
        double viol = a[2 * q] * x0 + a[2 * q + 1] * y0 - b[q];
        if (!(viol <= tol)) {
            goto outside;
        }
    }
    return 1;
outside:;
    double best = INFINITY, bx = x0, by = y0;
    int found = 0;
    /* the candidates: m edges, then the vertices (i < j) */
    Py_ssize_t count = m + m * (m - 1) / 2;
    Py_ssize_t i = 0, j = 0;
    for (Py_ssize_t c = 0; c < count; c++) {
        double cx, cy;
        if (c < m) {
            double ax = a[2 * c], ay = a[2 * c + 1];
            double viol = ax * x0 + ay * y0 - b[c];
            double norm2 = ax * ax + ay * ay;
            double step = norm2 > 0 ? viol / norm2 : NAN;
            cx = x0 - step * ax;
            cy = y0 - step * ay;
        }
        else {
            if (c == m) {
                i = 0;
                j = 1;
            }
            const double *a1 = a + 2 * i, *a2 = a + 2 * j;
            double b1 = b[i], b2 = b[j];
            double det = a1[0] * a2[1] - a1[1] * a2[0];
            int good = fabs(det) > SINGULAR;
            det = good ? det : 1.0;
            double vx = (b1 * a2[1] - b2 * a1[1]) / det;
            double vy = (a1[0] * b2 - a2[0] * b1) / det;
            cx = good ? vx : NAN;
            cy = good ? vy : NAN;
            if (++j == m) { /* the next pair */
                i++;
                j = i + 1;
            }
        }
        int keeps = 1;
        for (Py_ssize_t q = 0; q < m; q++) {
            double lhs = a[2 * q] * cx + a[2 * q + 1] * cy;
            if (!(lhs - b[q] <= tol)) {
                keeps = 0;
                break;
            }
        }
        if (!keeps) {
            continue;
        }
        double dx = cx - x0, dy = cy - y0;
        double dist = dx * dx + dy * dy;
        if (dist < best) { /* argmin: the first of equal distances */
            best = dist;
            bx = cx;
            by = cy;
            found = 1;
        }
    }
    if (found && isfinite(best)) {
        z[0] = bx;
        z[1] = by;
        return 1;
    }
    return 0;
}

#endif
