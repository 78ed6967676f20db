/* The bouncing ball that ball_me2.c (FMI 2.0) and ball_me3.c (FMI 3.0) wrap.
 *
 * States h and v: der(h) = v, der(v) = a - g. Real value references: h 0, der(h) 1, v 2,
 * der(v) 3, g 4, e 5 (restitution), a 6 (input), kick_at 7, kick 8, steps 9 (calls of
 * completedIntegratorStep), z 12 (the event indicator, h). When the ball reaches the floor (a
 * state event) v = -e*v and bounces counts; once bounces reaches max_bounces the model asks
 * to terminate. A bounce slower than V_MIN leaves the ball resting on the floor (without
 * this, bounces come ever closer until the integrator is stuck among them, a Zeno point),
 * until an input lifts it. At t = kick_at (a time event) v += kick.
 */
#ifndef BALL_MODEL_H
#define BALL_MODEL_H

#include <float.h>
#include <stdint.h>
#include <stdlib.h>

#define V_MIN 0.1

typedef struct {
    double time, h, v, g, e, a, kick_at, kick, steps;
    int32_t bounces, max_bounces;
    int kicked, terminated, resting;
} Ball;

/* Resting holds the ball only while its input does not lift it. */
static int ball_at_rest(const Ball *b) { return b->resting && b->a <= b->g; }

static void ball_derivatives(const Ball *b, double *dh, double *dv) {
    *dh = ball_at_rest(b) ? 0 : b->v;
    *dv = ball_at_rest(b) ? 0 : b->a - b->g;
}

static double ball_indicator(const Ball *b) { return ball_at_rest(b) ? 1.0 : b->h; }

static Ball *ball_new(void) {
    Ball *b = calloc(1, sizeof(Ball));
    if (b) {
        b->h = 1.0; b->g = 9.81; b->e = 0.7; b->kick_at = -1; b->max_bounces = 1000000;
    }
    return b;
}

/* Event iteration: what an event update and the co-simulation step both do at an event. */
static void ball_update(Ball *b) {
    if (b->h <= 0 && b->v < 0) {
        b->h = DBL_MIN;  /* above the floor: the indicator does not start the next interval at 0 */
        b->v = -b->e * b->v;
        b->bounces++;
        if (b->bounces >= b->max_bounces) b->terminated = 1;
        if (b->v < V_MIN) {
            b->h = b->v = 0;
            b->resting = 1;
        }
    }
    if (!b->kicked && b->kick_at >= 0 && b->time >= b->kick_at - 1e-12) {
        b->v += b->kick;
        b->kicked = 1;
    }
    if (b->resting && (b->v > 0 || b->a > b->g)) b->resting = 0;  /* kicked or lifted off the floor */
}

/* Where a Real variable lives (derived ones in *scratch); NULL for no such variable. */
static double *ball_real(Ball *b, uint32_t vr, double *scratch) {
    switch (vr) {
    case 0: return &b->h;
    case 2: return &b->v;
    case 4: return &b->g;
    case 5: return &b->e;
    case 6: return &b->a;
    case 7: return &b->kick_at;
    case 8: return &b->kick;
    case 9: return &b->steps;
    case 1: case 3: {
        double dh, dv;
        ball_derivatives(b, &dh, &dv);
        *scratch = vr == 1 ? dh : dv;
        return scratch;
    }
    case 12: *scratch = ball_indicator(b); return scratch;
    default: return NULL;
    }
}

/* Derived variables cannot be set. */
static int ball_settable(uint32_t vr) { return vr != 1 && vr != 3 && vr != 9 && vr != 12; }

#endif
