/* The bouncing ball (ball_model.h) as an FMI 3.0 Model Exchange FMU. Int32: bounces (vr 10),
 * max_bounces (vr 11); the Float64 variables as in ball_model.h.
 * The FMI 3 types are written out (fmi3Status an int, fmi3Boolean a C bool, fmi3ValueReference
 * a uint32_t): FMPy binds every function of the standard, so the ones the tests never call are
 * plain stubs that return fmi3Error, with no prototype from the header to match.
 */
#include <stdbool.h>
#include <stddef.h>
#include <string.h>
#include "ball_model.h"

#define EXPORT __attribute__((visibility("default")))
#define OK 0
#define ERROR 3

EXPORT const char *fmi3GetVersion(void) { return "3.0"; }
EXPORT int fmi3SetDebugLogging(void *c, bool on, size_t n, const char *const cats[]) { return OK; }

EXPORT void *fmi3InstantiateModelExchange(const char *name, const char *token, const char *resources, bool visible,
                                          bool logging, void *env, void *log) {
    return ball_new();
}
EXPORT void fmi3FreeInstance(void *c) { free(c); }
EXPORT int fmi3EnterInitializationMode(void *c, bool tolDef, double tol, double t0, bool stopDef, double stop) {
    ((Ball *)c)->time = t0;
    return OK;
}
EXPORT int fmi3ExitInitializationMode(void *c) { return OK; }
EXPORT int fmi3EnterEventMode(void *c) { return OK; }
EXPORT int fmi3Terminate(void *c) { return OK; }
EXPORT int fmi3Reset(void *c) { return OK; }

EXPORT int fmi3GetFloat64(void *c, const uint32_t vr[], size_t n, double v[], size_t nv) {
    double scratch;
    for (size_t i = 0; i < n; i++) {
        double *p = ball_real(c, vr[i], &scratch);
        if (!p) return ERROR;
        v[i] = *p;
    }
    return OK;
}
EXPORT int fmi3SetFloat64(void *c, const uint32_t vr[], size_t n, const double v[], size_t nv) {
    double scratch;
    for (size_t i = 0; i < n; i++) {
        if (!ball_settable(vr[i])) return ERROR;
        double *p = ball_real(c, vr[i], &scratch);
        if (!p) return ERROR;
        *p = v[i];
    }
    return OK;
}
EXPORT int fmi3GetInt32(void *c, const uint32_t vr[], size_t n, int32_t v[], size_t nv) {
    Ball *b = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 10) v[i] = b->bounces;
        else if (vr[i] == 11) v[i] = b->max_bounces;
        else return ERROR;
    }
    return OK;
}
EXPORT int fmi3SetInt32(void *c, const uint32_t vr[], size_t n, const int32_t v[], size_t nv) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 11) return ERROR;
        ((Ball *)c)->max_bounces = v[i];
    }
    return OK;
}

EXPORT int fmi3GetFMUState(void *c, void **s) {
    if (!*s) *s = malloc(sizeof(Ball));
    if (!*s) return ERROR;
    memcpy(*s, c, sizeof(Ball));
    return OK;
}
EXPORT int fmi3SetFMUState(void *c, void *s) { memcpy(c, s, sizeof(Ball)); return OK; }
EXPORT int fmi3FreeFMUState(void *c, void **s) { free(*s); *s = NULL; return OK; }
EXPORT int fmi3SerializedFMUStateSize(void *c, void *s, size_t *n) { *n = sizeof(Ball); return OK; }
EXPORT int fmi3SerializeFMUState(void *c, void *s, uint8_t b[], size_t n) {
    if (n != sizeof(Ball)) return ERROR;
    memcpy(b, s, n);
    return OK;
}
EXPORT int fmi3DeserializeFMUState(void *c, const uint8_t b[], size_t n, void **s) {
    if (n != sizeof(Ball)) return ERROR;
    *s = malloc(n);
    if (!*s) return ERROR;
    memcpy(*s, b, n);
    return OK;
}

EXPORT int fmi3EnterContinuousTimeMode(void *c) { return OK; }
EXPORT int fmi3CompletedIntegratorStep(void *c, bool noSetPrior, bool *enterEventMode, bool *terminate) {
    ((Ball *)c)->steps += 1;
    *enterEventMode = false;
    *terminate = false;
    return OK;
}
EXPORT int fmi3SetTime(void *c, double t) { ((Ball *)c)->time = t; return OK; }
EXPORT int fmi3SetContinuousStates(void *c, const double x[], size_t nx) {
    if (nx != 2) return ERROR;
    ((Ball *)c)->h = x[0];
    ((Ball *)c)->v = x[1];
    return OK;
}
EXPORT int fmi3GetContinuousStateDerivatives(void *c, double dx[], size_t nx) {
    Ball *b = c;
    if (nx != 2) return ERROR;
    ball_derivatives(b, &dx[0], &dx[1]);
    return OK;
}
EXPORT int fmi3GetEventIndicators(void *c, double z[], size_t nz) {
    if (nz != 1) return ERROR;
    z[0] = ball_indicator(c);
    return OK;
}
EXPORT int fmi3GetContinuousStates(void *c, double x[], size_t nx) {
    if (nx != 2) return ERROR;
    x[0] = ((Ball *)c)->h;
    x[1] = ((Ball *)c)->v;
    return OK;
}
EXPORT int fmi3GetNominalsOfContinuousStates(void *c, double x[], size_t nx) {
    for (size_t i = 0; i < nx; i++) x[i] = 1.0;
    return OK;
}
EXPORT int fmi3GetNumberOfEventIndicators(void *c, size_t *n) { *n = 1; return OK; }
EXPORT int fmi3GetNumberOfContinuousStates(void *c, size_t *n) { *n = 2; return OK; }
EXPORT int fmi3UpdateDiscreteStates(void *c, bool *needUpdate, bool *terminate, bool *nominalsChanged,
                                    bool *valuesChanged, bool *nextDefined, double *next) {
    Ball *b = c;
    ball_update(b);
    *needUpdate = false;
    *terminate = b->terminated;
    *nominalsChanged = false;
    *valuesChanged = true;
    *nextDefined = !b->kicked && b->kick_at >= 0;
    *next = b->kick_at;
    return OK;
}

/* The rest of the standard, never called here. */
#define STUB(name) EXPORT int name(void) { return ERROR; }
STUB(fmi3ActivateModelPartition) STUB(fmi3DoStep) STUB(fmi3EnterConfigurationMode) STUB(fmi3EnterStepMode)
STUB(fmi3EvaluateDiscreteStates) STUB(fmi3ExitConfigurationMode) STUB(fmi3GetAdjointDerivative)
STUB(fmi3GetBinary) STUB(fmi3GetBoolean) STUB(fmi3GetClock) STUB(fmi3GetDirectionalDerivative)
STUB(fmi3GetFloat32) STUB(fmi3GetInt16) STUB(fmi3GetInt64) STUB(fmi3GetInt8) STUB(fmi3GetIntervalDecimal)
STUB(fmi3GetIntervalFraction) STUB(fmi3GetNumberOfVariableDependencies) STUB(fmi3GetOutputDerivatives)
STUB(fmi3GetShiftDecimal) STUB(fmi3GetShiftFraction) STUB(fmi3GetString) STUB(fmi3GetUInt16) STUB(fmi3GetUInt32)
STUB(fmi3GetUInt64) STUB(fmi3GetUInt8) STUB(fmi3GetVariableDependencies) STUB(fmi3InstantiateCoSimulation)
STUB(fmi3InstantiateScheduledExecution) STUB(fmi3SetBinary) STUB(fmi3SetBoolean) STUB(fmi3SetClock)
STUB(fmi3SetFloat32) STUB(fmi3SetInt16) STUB(fmi3SetInt64) STUB(fmi3SetInt8) STUB(fmi3SetIntervalDecimal)
STUB(fmi3SetIntervalFraction) STUB(fmi3SetShiftDecimal) STUB(fmi3SetShiftFraction) STUB(fmi3SetString)
STUB(fmi3SetUInt16) STUB(fmi3SetUInt32) STUB(fmi3SetUInt64) STUB(fmi3SetUInt8)
