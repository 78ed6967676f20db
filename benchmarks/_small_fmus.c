/* Small FMI 2.0 co-simulation FMUs for the in-process benchmark and the cross-check against
 * other engines, one source compiled once per model (-DMODEL=...):
 *
 *   MODEL 1, Dahlquist:   der(x) = -k x (x(0) = 1, k = 1), forward Euler over the step;
 *   MODEL 2, Feedthrough: y = u, at once (a direct feedthrough);
 *   MODEL 3, VanDerPol:   der(x0) = x1, der(x1) = mu (1 - x0^2) x1 - x0 (x0(0) = 2, mu = 1),
 *                         forward Euler in 10 substeps per step;
 *   MODEL 4, Types:       a direct feedthrough of each type: ry = gain ru (Real), iy = iu + offset
 *                         (Integer), by = !bu (Boolean);
 *   MODEL 5, Ball:        a bouncing ball, h'' = -g, integrated exactly; each floor contact inside a
 *                         step is located exactly (a state event: v = -e v there, bounces + 1) and
 *                         the ball rests once it leaves the floor slower than 1 mm/s. Outputs h, v
 *                         (Real), bounces (Integer), falling (Boolean, v < 0).
 *   MODEL 6, Constant:    y = 3;
 *   MODEL 7, LateFeedthrough: y = u, computed only when the FMU leaves initialisation mode and in
 *                         its steps, never in a getter (as pythonfmu FMUs commonly do): an importer
 *                         that sets its start input after exitInitializationMode starts it late.
 *
 * Value references (see benchmarks/_small_fmus.py): Reals 0..N_REAL-1, Integers from 100,
 * Booleans from 200. The state can be saved and restored (fmi2Get/SetFMUstate) but not
 * serialised.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

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

FMI2_Export const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
FMI2_Export const char *fmi2GetVersion(void) { return fmi2Version; }
FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi2OK;
}
FMI2_Export fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                                          const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                          fmi2Boolean logging) {
    (void)name; (void)guid; (void)resources; (void)functions; (void)visible; (void)logging;
    if (type != fmi2CoSimulation) return NULL;
    Instance *inst = calloc(1, sizeof *inst);
    if (inst) start(inst);
    return inst;
}
FMI2_Export void fmi2FreeInstance(fmi2Component c) { free(c); }
FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                                           fmi2Boolean stop_defined, fmi2Real stop) {
    (void)c; (void)tol_defined; (void)tol; (void)start; (void)stop_defined; (void)stop;
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component c) { settle(c); return fmi2OK; }
FMI2_Export fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
FMI2_Export fmi2Status fmi2Reset(fmi2Component c) {
    start(c);
    return fmi2OK;
}
/* One getter and one setter per type, over the type's array from its first value reference. */
#define ACCESS(Type, ctype, array, first, count)                                                           \
    FMI2_Export fmi2Status fmi2Get##Type(fmi2Component c, const fmi2ValueReference vr[], size_t n,        \
                                         ctype value[]) {                                                  \
        Instance *inst = c;                                                                                \
        on_get(inst);                                                                                      \
        for (size_t k = 0; k < n; k++) {                                                                   \
            if (vr[k] < (first) || vr[k] >= (first) + (count)) return fmi2Error;                           \
            value[k] = inst->array[vr[k] - (first)];                                                       \
        }                                                                                                  \
        return fmi2OK;                                                                                     \
    }                                                                                                      \
    FMI2_Export fmi2Status fmi2Set##Type(fmi2Component c, const fmi2ValueReference vr[], size_t n,        \
                                         const ctype value[]) {                                            \
        Instance *inst = c;                                                                                \
        for (size_t k = 0; k < n; k++) {                                                                   \
            if (vr[k] < (first) || vr[k] >= (first) + (count)) return fmi2Error;                           \
            inst->array[vr[k] - (first)] = value[k];                                                       \
        }                                                                                                  \
        return fmi2OK;                                                                                     \
    }
ACCESS(Real, fmi2Real, r, 0u, N_REAL)
ACCESS(Integer, fmi2Integer, i, (unsigned)INT0, N_INT)
ACCESS(Boolean, fmi2Boolean, b, (unsigned)BOOL0, N_BOOL)
FMI2_Export fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t0, fmi2Real h, fmi2Boolean no_prior) {
    (void)t0; (void)no_prior;
    step(c, h);
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Instance *copy = *state ? *state : malloc(sizeof *copy);
    if (!copy) return fmi2Error;
    memcpy(copy, c, sizeof *copy);
    *state = copy;
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    memcpy(c, state, sizeof(Instance));
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    (void)c;
    free(*state);
    *state = NULL;
    return fmi2OK;
}
#define REFUSE(...) { (void)c; return fmi2Error; }
FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) REFUSE(s, n)
FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) REFUSE(s, b, n)
FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s)
    REFUSE(b, n, s)
FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[])
    REFUSE(vr, n, v)
FMI2_Export fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[])
    REFUSE(vr, n, v)
FMI2_Export fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                                    const fmi2ValueReference z[], size_t nz, const fmi2Real du[],
                                                    fmi2Real dz[]) REFUSE(u, nu, z, nz, du, dz)
FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                   const fmi2Integer order[], const fmi2Real v[]) REFUSE(vr, n, order, v)
FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                    const fmi2Integer order[], fmi2Real v[]) REFUSE(vr, n, order, v)
FMI2_Export fmi2Status fmi2CancelStep(fmi2Component c) REFUSE()
FMI2_Export fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) REFUSE(s, v)
FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) REFUSE(s, v)
FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) REFUSE(s, v)
FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) REFUSE(s, v)
FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) REFUSE(s, v)
