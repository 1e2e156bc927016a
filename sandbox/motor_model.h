/* The residual detector's motor model of one control period, for one vehicle.
 *
 * Included by sandbox/model/_kernels.c (motor_model, the model alone) and
 * sandbox/behaviour/_residual.c (the detector's whole pass of a period), after
 * accel.h: what the residual detector's numpy motor model does to one row.
 */

#ifndef SANDBOX_MOTOR_MODEL_H
#define SANDBOX_MOTOR_MODEL_H

/* Advance ``p`` (x, y, heading), ``v`` (the body's velocity, 2), ``*w`` (its turn
 * rate) and ``*travel`` by one period ``h`` of ``substeps`` substeps of ``dts``
 * toward the commands ``(v1, v2)``, by at most ``accel dts`` and ``turn dts`` a
 * substep (the heading of the target velocity is the period's mid-point). */
static inline void
motor_period(double *p, double *v, double *w, double *travel, double v1, double v2,
             double accel, double turn, double h, double dts, long substeps)
{
    double heading = p[2] + 0.5 * v2 * h;
    double t0 = v1 * cos(heading), t1 = v1 * sin(heading);
    double lin = accel * dts, ang = turn * dts;
    double sx = p[0], sy = p[1];
    double vx = v[0], vy = v[1], rate = *w;
    for (long s = 0; s < substeps; s++) {
        p[0] = p[0] + vx * dts;
        p[1] = p[1] + vy * dts;
        p[2] = p[2] + rate * dts;
        double d0 = t0 - vx, d1 = t1 - vy;
        double scale = 1.0;
        /* The norm is needed only where it may exceed lin: not where the sum of
         * squares is below (lin / 2)^2 (lin^2 a normal number), whose rounding is
         * far from moving the norm past lin (and never with lin infinite). */
        double q = d0 * d0 + d1 * d1;
        if (!(q < 0.25 * lin * lin && lin > 1e-100)) {
            double norm = hypot(d0, d1);
            scale = norm > lin ? lin / larger(norm, 1e-300) : 1.0;
        }
        vx = vx + d0 * scale;
        vy = vy + d1 * scale;
        rate = rate + clamp(v2 - rate, -ang, ang);
    }
    v[0] = vx;
    v[1] = vy;
    *w = rate;
    *travel = *travel + hypot(p[0] - sx, p[1] - sy);
}

#endif
