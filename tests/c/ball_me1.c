/* The bouncing ball (ball_model.h) as an FMI 1.0 Model Exchange FMU, model identifier "ball1":
 * every function named ball1_fmi..., as FMI 1.0 has them. Integers: bounces (vr 0),
 * max_bounces (vr 1). No state get/set (FMI 1.0 has none).
 */
#include <stddef.h> /* fmpy's fmi1Functions.h uses size_t without it */
#include "ball_model.h"
#include "fmi1Functions.h"

#define F(name) ball1_##name
#define EXPORT __attribute__((visibility("default")))

EXPORT const char *F(fmiGetModelTypesPlatform)(void) { return "standard32"; }
EXPORT const char *F(fmiGetVersion)(void) { return "1.0"; }
EXPORT fmi1Component F(fmiInstantiateModel)(fmi1String name, fmi1String guid, fmi1CallbackFunctions functions,
                                            fmi1Boolean logging) {
    return ball_new();
}
EXPORT void F(fmiFreeModelInstance)(fmi1Component c) { free(c); }
EXPORT fmi1Status F(fmiSetDebugLogging)(fmi1Component c, fmi1Boolean on) { return fmi1OK; }
EXPORT fmi1Status F(fmiSetTime)(fmi1Component c, fmi1Real t) { ((Ball *)c)->time = t; return fmi1OK; }
EXPORT fmi1Status F(fmiSetContinuousStates)(fmi1Component c, const fmi1Real x[], size_t nx) {
    if (nx != 2) return fmi1Error;
    ((Ball *)c)->h = x[0];
    ((Ball *)c)->v = x[1];
    return fmi1OK;
}
EXPORT fmi1Status F(fmiCompletedIntegratorStep)(fmi1Component c, fmi1Boolean *callEventUpdate) {
    ((Ball *)c)->steps += 1;
    *callEventUpdate = fmi1False;
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1Real v[]) {
    double scratch;
    for (size_t i = 0; i < n; i++) {
        double *p = ball_real(c, vr[i], &scratch);
        if (!p) return fmi1Error;
        v[i] = *p;
    }
    return fmi1OK;
}
EXPORT fmi1Status F(fmiSetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Real v[]) {
    double scratch;
    for (size_t i = 0; i < n; i++) {
        if (!ball_settable(vr[i])) return fmi1Error;
        double *p = ball_real(c, vr[i], &scratch);
        if (!p) return fmi1Error;
        *p = v[i];
    }
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1Integer v[]) {
    Ball *b = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 0) v[i] = b->bounces;
        else if (vr[i] == 1) v[i] = b->max_bounces;
        else return fmi1Error;
    }
    return fmi1OK;
}
EXPORT fmi1Status F(fmiSetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Integer v[]) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 1) return fmi1Error;
        ((Ball *)c)->max_bounces = v[i];
    }
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1Boolean v[]) {
    return n ? fmi1Error : fmi1OK;
}
EXPORT fmi1Status F(fmiSetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1Boolean v[]) {
    return n ? fmi1Error : fmi1OK;
}
EXPORT fmi1Status F(fmiGetString)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1String v[]) {
    return n ? fmi1Error : fmi1OK;
}
EXPORT fmi1Status F(fmiSetString)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1String v[]) {
    return n ? fmi1Error : fmi1OK;
}
static void event_info(Ball *b, fmi1EventInfo *info) {
    info->iterationConverged = fmi1True;
    info->stateValueReferencesChanged = fmi1False;
    info->stateValuesChanged = fmi1True;
    info->terminateSimulation = b->terminated;
    info->upcomingTimeEvent = !b->kicked && b->kick_at >= 0;
    info->nextEventTime = b->kick_at;
}
EXPORT fmi1Status F(fmiInitialize)(fmi1Component c, fmi1Boolean tolControlled, fmi1Real relTol, fmi1EventInfo *info) {
    ball_update(c);
    event_info(c, info);
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetDerivatives)(fmi1Component c, fmi1Real dx[], size_t nx) {
    if (nx != 2) return fmi1Error;
    ball_derivatives(c, &dx[0], &dx[1]);
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetEventIndicators)(fmi1Component c, fmi1Real z[], size_t nz) {
    if (nz != 1) return fmi1Error;
    z[0] = ball_indicator(c);
    return fmi1OK;
}
EXPORT fmi1Status F(fmiEventUpdate)(fmi1Component c, fmi1Boolean intermediate, fmi1EventInfo *info) {
    ball_update(c);
    event_info(c, info);
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetContinuousStates)(fmi1Component c, fmi1Real x[], size_t nx) {
    if (nx != 2) return fmi1Error;
    x[0] = ((Ball *)c)->h;
    x[1] = ((Ball *)c)->v;
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetNominalContinuousStates)(fmi1Component c, fmi1Real x[], size_t nx) {
    for (size_t i = 0; i < nx; i++) x[i] = 1.0;
    return fmi1OK;
}
EXPORT fmi1Status F(fmiGetStateValueReferences)(fmi1Component c, fmi1ValueReference vrx[], size_t nx) {
    if (nx != 2) return fmi1Error;
    vrx[0] = 0;
    vrx[1] = 2;
    return fmi1OK;
}
EXPORT fmi1Status F(fmiTerminate)(fmi1Component c) { return fmi1OK; }
