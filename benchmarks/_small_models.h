/* The small models of benchmarks/_small_fmus.c (FMI 2.0) and benchmarks/_small_fmus1.c
 * (FMI 1.0), one compiled per -DMODEL=...: their variables, start values, step and settle.
 * Value references: each type's variables in order from its first (Reals from 0, Integers from
 * INT0, Booleans from BOOL0; benchmarks/_small_fmus.py). */
#ifndef SMALL_MODELS_H
#define SMALL_MODELS_H
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define INT0 100
#define BOOL0 200

#if MODEL == 1
#define N_REAL 2 /* k, x */
#define N_INT 0
#define N_BOOL 0
static const double START_R[] = {1.0, 1.0};
#elif MODEL == 2
#define N_REAL 2 /* u, y */
#define N_INT 0
#define N_BOOL 0
static const double START_R[] = {0.0, 0.0};
#elif MODEL == 3
#define N_REAL 3 /* mu, x0, x1 */
#define N_INT 0
#define N_BOOL 0
static const double START_R[] = {1.0, 2.0, 0.0};
#elif MODEL == 4
#define N_REAL 3 /* gain, ru, ry */
#define N_INT 3  /* offset, iu, iy */
#define N_BOOL 2 /* bu, by */
static const double START_R[] = {1.0, 0.0, 0.0};
static const int START_I[] = {0, 0, 0};
static const int START_B[] = {0, 1};
#elif MODEL == 5
#define N_REAL 4 /* h, v, g, e */
#define N_INT 1  /* bounces */
#define N_BOOL 1 /* falling */
static const double START_R[] = {1.0, 0.0, 9.81, 0.8};
static const int START_I[] = {0};
static const int START_B[] = {0};
#elif MODEL == 6
#define N_REAL 1 /* y */
#define N_INT 0
#define N_BOOL 0
static const double START_R[] = {3.0};
#elif MODEL == 7
#define N_REAL 2 /* u, y */
#define N_INT 0
#define N_BOOL 0
static const double START_R[] = {0.0, 0.0};
#define NO_SETTLE_ON_GET
#else
#error "MODEL must be 1 to 7"
#endif

typedef struct {
    double r[N_REAL];
    int i[N_INT > 0 ? N_INT : 1];
    int b[N_BOOL > 0 ? N_BOOL : 1];
    int resting;
} Instance;

static void start(Instance *s) {
    memset(s, 0, sizeof *s);
    memcpy(s->r, START_R, sizeof START_R);
#if N_INT > 0
    memcpy(s->i, START_I, sizeof START_I);
#endif
#if N_BOOL > 0
    memcpy(s->b, START_B, sizeof START_B);
#endif
}

#if MODEL == 1
static void step(Instance *s, double h) { s->r[1] += h * (-s->r[0] * s->r[1]); }
static void settle(Instance *s) { (void)s; }
#elif MODEL == 2
static void step(Instance *s, double h) { (void)s; (void)h; }
static void settle(Instance *s) { s->r[1] = s->r[0]; }
#elif MODEL == 3
static void step(Instance *s, double h) {
    double dt = h / 10.0, *r = s->r;
    for (int i = 0; i < 10; i++) {
        double x0 = r[1], x1 = r[2];
        r[1] = x0 + dt * x1;
        r[2] = x1 + dt * (r[0] * (1.0 - x0 * x0) * x1 - x0);
    }
}
static void settle(Instance *s) { (void)s; }
#elif MODEL == 4
static void step(Instance *s, double h) { (void)s; (void)h; }
static void settle(Instance *s) {
    s->r[2] = s->r[0] * s->r[1];
    s->i[2] = s->i[1] + s->i[0];
    s->b[1] = !s->b[0];
}
#elif MODEL == 5
static void step(Instance *s, double left) {
    double *r = s->r, g = r[2], e = r[3];
    while (left > 0.0 && !s->resting) {
        /* The next contact: h + v tau - g tau^2 / 2 = 0, its positive root. */
        double tau = (r[1] + sqrt(fmax(0.0, r[1] * r[1] + 2.0 * g * r[0]))) / g;
        if (tau > left) {
            r[0] += left * (r[1] - 0.5 * g * left);
            r[1] -= g * left;
            break;
        }
        r[0] = 0.0;
        r[1] = -e * (r[1] - g * tau);
        s->i[0] += 1;
        left -= tau;
        if (r[1] < 1e-3) {
            r[1] = 0.0;
            s->resting = 1;
        }
    }
}
static void settle(Instance *s) { s->b[0] = s->r[1] < 0.0; }
#elif MODEL == 6
static void step(Instance *s, double h) { (void)s; (void)h; }
static void settle(Instance *s) { (void)s; }
#elif MODEL == 7
static void step(Instance *s, double h) { (void)h; s->r[1] = s->r[0]; }
static void settle(Instance *s) { s->r[1] = s->r[0]; }
#endif
#ifdef NO_SETTLE_ON_GET
static void on_get(Instance *s) { (void)s; }
#else
static void on_get(Instance *s) { settle(s); }
#endif

#endif
