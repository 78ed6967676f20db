/* A bouncing ball as an FMI 2.0 FMU for the Model Exchange tests, with a co-simulation
 * interface too (its own explicit Euler at 1 ms), so one file tests both and the choice.
 *
 * States h (vr 0, der vr 1) and v (vr 2, der vr 3): der(h) = v, der(v) = a - g.
 * Parameters g (vr 4), e (vr 5, restitution), kick_at (vr 7), kick (vr 8); input a (vr 6).
 * Event indicator h: when the ball reaches the floor (a state event), v = -e*v and
 * bounces (Integer vr 0) counts; once bounces reaches max_bounces (Integer vr 1) the FMU
 * asks to terminate. At t = kick_at (a time event) v += kick.
 * completedIntegratorStep is needed (it only counts calls, vr 9). Its state can be got,
 * set and serialised (canGetAndSetFMUstate, canSerializeFMUstate): a struct copied whole.
 */
#include <float.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

typedef struct {
    double time, h, v, g, e, a, kick_at, kick, steps;
    int bounces, max_bounces, kicked, terminated;
} Ball;

static void derivatives(const Ball *b, double *dh, double *dv) {
    *dh = b->v;
    *dv = b->a - b->g;
}

/* Event iteration: what fmi2NewDiscreteStates and the CS doStep both do at an event. */
static void update(Ball *b) {
    if (b->h <= 0 && b->v < 0) {
        b->h = DBL_MIN;  /* above the floor: the indicator does not start the next interval at 0 */
        b->v = -b->e * b->v;
        b->bounces++;
        if (b->bounces >= b->max_bounces) b->terminated = 1;
    }
    if (!b->kicked && b->kick_at >= 0 && b->time >= b->kick_at - 1e-12) {
        b->v += b->kick;
        b->kicked = 1;
    }
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) { return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Ball *b = calloc(1, sizeof(Ball));
    if (!b) return NULL;
    b->h = 1.0; b->g = 9.81; b->e = 0.7; b->kick_at = -1; b->max_bounces = 1000000;
    return b;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real t0, fmi2Boolean stopDef,
                               fmi2Real stop) {
    ((Ball *)c)->time = t0;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { return fmi2OK; }

static double *real_at(Ball *b, fmi2ValueReference vr, double *scratch) {
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
        derivatives(b, &dh, &dv);
        *scratch = vr == 1 ? dh : dv;
        return scratch;
    }
    default: return NULL;
    }
}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    double scratch;
    for (size_t i = 0; i < n; i++) {
        double *p = real_at(c, vr[i], &scratch);
        if (!p) return fmi2Error;
        v[i] = *p;
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    double scratch;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 1 || vr[i] == 3 || vr[i] == 9) return fmi2Error;
        double *p = real_at(c, vr[i], &scratch);
        if (!p) return fmi2Error;
        *p = v[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Ball *b = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 0) v[i] = b->bounces;
        else if (vr[i] == 1) v[i] = b->max_bounces;
        else return fmi2Error;
    }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 1) return fmi2Error;
        ((Ball *)c)->max_bounces = v[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { return n ? fmi2Error : fmi2OK; }

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    if (!*s) *s = malloc(sizeof(Ball));
    if (!*s) return fmi2Error;
    memcpy(*s, c, sizeof(Ball));
    return fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { memcpy(c, s, sizeof(Ball)); return fmi2OK; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { free(*s); *s = NULL; return fmi2OK; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { *n = sizeof(Ball); return fmi2OK; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    if (n != sizeof(Ball)) return fmi2Error;
    memcpy(b, s, n);
    return fmi2OK;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    if (n != sizeof(Ball)) return fmi2Error;
    *s = malloc(n);
    if (!*s) return fmi2Error;
    memcpy(*s, b, n);
    return fmi2OK;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real du[], fmi2Real dz[]) {
    return fmi2Error;
}

/* --- Model Exchange ------------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    Ball *b = c;
    update(b);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = b->terminated;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2True;
    info->nextEventTimeDefined = !b->kicked && b->kick_at >= 0;
    info->nextEventTime = b->kick_at;
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetPrior, fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminate) {
    ((Ball *)c)->steps += 1;
    *enterEventMode = fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((Ball *)c)->time = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    if (nx != 2) return fmi2Error;
    ((Ball *)c)->h = x[0];
    ((Ball *)c)->v = x[1];
    return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    if (nx != 2) return fmi2Error;
    derivatives(c, &dx[0], &dx[1]);
    return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) {
    if (nz != 1) return fmi2Error;
    z[0] = ((Ball *)c)->h;
    return fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    if (nx != 2) return fmi2Error;
    x[0] = ((Ball *)c)->h;
    x[1] = ((Ball *)c)->v;
    return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    for (size_t i = 0; i < nx; i++) x[i] = 1.0;
    return fmi2OK;
}

/* --- Co-simulation: explicit Euler at 1 ms inside each doStep ------------------------------ */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[],
                                       const fmi2Real v[]) { return fmi2Error; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[],
                                        fmi2Real v[]) { return fmi2Error; }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Ball *b = c;
    double end = t + h;
    while (b->time < end - 1e-12) {
        double dt = end - b->time < 1e-3 ? end - b->time : 1e-3, dh, dv;
        derivatives(b, &dh, &dv);
        b->h += dt * dh;
        b->v += dt * dv;
        b->time += dt;
        update(b);
        if (b->terminated) return fmi2Discard;
    }
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) { return fmi2Discard; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    if (k != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = ((Ball *)c)->time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) { return fmi2Discard; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    if (k != fmi2Terminated) return fmi2Discard;
    *v = ((Ball *)c)->terminated;
    return fmi2OK;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) { return fmi2Discard; }
