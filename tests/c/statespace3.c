/* A linear state-space model as an FMI 3.0 co-simulation FMU with array variables:
 *   dx/dt = A x + B u,  y = C x + D u,  x(t0) = x0,
 * x of n, u of m, y of r elements, their sizes set by the structural parameters m, n, r
 * (UInt64, vr 1-3; 1 to MAXD each) before initialisation. A (vr 4, n x n), B (5, n x m),
 * C (6, r x n), D (7, r x m), x0 (8, n), u (9, m), y (10, r), x (11, n); a scalar input g
 * (12) added to every element of dx/dt, a scalar output s (13), the sum of y, and an output
 * pair (14) of a fixed size 2: x[0] and the time. Beside them, the FMI 3 types FMI 2 lacks or
 * names otherwise: a String input label (15) and output greeting (16, "hello " + label), a
 * Binary input blob (17) and output blob_out (18, blob reversed), a Float32 input k32 (22) and
 * output s32 (19, s + k32 in single precision).
 * A clocked partition, for the descriptions that declare the input clock tick (20): at each
 * tick, in event mode, held (23) takes s as it is then, and ticks (24) counts the ticks. The
 * FMU is in event mode after initialisation when the importer asked for it, and between
 * fmi3EnterEventMode and fmi3EnterStepMode; a step or a clock set in the wrong mode fails.
 * Arrays are row-major, as FMI 3 serialises them. A step of h is taken as 10 explicit Euler
 * steps, so that fmpy and hycosim, calling it on the same grid, get the same values.
 * The FMI 3 types are written out, as in ball_me3.c; functions never called are stubs.
 */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define EXPORT __attribute__((visibility("default")))
#define OK 0
#define ERROR 3
#define MAXD 16
#define MAXTEXT 256
#define MAXBLOB 1024

typedef struct {
    uint64_t m, n, r;
    double A[MAXD * MAXD], B[MAXD * MAXD], C[MAXD * MAXD], D[MAXD * MAXD];
    double x0[MAXD], u[MAXD], x[MAXD], g;
    double time;
    int initialised;
    char label[MAXTEXT], greeting[MAXTEXT + 6];
    uint8_t blob[MAXBLOB], blob_out[MAXBLOB];
    size_t blob_size;
    float k32;
    double held, ticks;
    bool event_mode_used, in_event, tick_active;
} Model;

/* The defaults of every array for the sizes set: the model description's start values are
 * these at m = 2, n = 3, r = 3. */
static void defaults(Model *s) {
    for (uint64_t i = 0; i < s->n; i++) {
        for (uint64_t j = 0; j < s->n; j++)
            s->A[i * s->n + j] = i == j ? -(double)(i + 1) : (j == i + 1 ? 0.5 : 0.0);
        for (uint64_t k = 0; k < s->m; k++) s->B[i * s->m + k] = k == i % s->m ? 1.0 : 0.0;
        s->x0[i] = 1.0 / (double)(i + 1);
    }
    for (uint64_t l = 0; l < s->r; l++) {
        for (uint64_t i = 0; i < s->n; i++) s->C[l * s->n + i] = l == i % s->r ? 1.0 : (i == 0 ? 0.25 : 0.0);
        for (uint64_t k = 0; k < s->m; k++) s->D[l * s->m + k] = l == k ? 0.1 : 0.0;
    }
    memset(s->u, 0, sizeof s->u);
}

static void outputs(const Model *s, double y[]) {
    for (uint64_t l = 0; l < s->r; l++) {
        double v = 0.0;
        for (uint64_t i = 0; i < s->n; i++) v += s->C[l * s->n + i] * s->x[i];
        for (uint64_t k = 0; k < s->m; k++) v += s->D[l * s->m + k] * s->u[k];
        y[l] = v;
    }
}

/* Where the elements of array vr live, and how many there are (0: not an array of this model). */
static double *array(Model *s, uint32_t vr, size_t *count) {
    switch (vr) {
    case 4: *count = s->n * s->n; return s->A;
    case 5: *count = s->n * s->m; return s->B;
    case 6: *count = s->r * s->n; return s->C;
    case 7: *count = s->r * s->m; return s->D;
    case 8: *count = s->n; return s->x0;
    case 9: *count = s->m; return s->u;
    case 11: *count = s->n; return s->x;
    case 12: *count = 1; return &s->g;
    case 23: *count = 1; return &s->held;
    case 24: *count = 1; return &s->ticks;
    default: *count = 0; return NULL;
    }
}

EXPORT const char *fmi3GetVersion(void) { return "3.0"; }
EXPORT int fmi3SetDebugLogging(void *c, bool on, size_t n, const char *const cats[]) { return OK; }

EXPORT void *fmi3InstantiateCoSimulation(const char *name, const char *token, const char *resources, bool visible,
                                         bool logging, bool eventModeUsed, bool earlyReturnAllowed,
                                         const uint32_t required[], size_t nRequired, void *env, void *log,
                                         void *intermediateUpdate) {
    Model *s = calloc(1, sizeof(Model));
    if (!s) return NULL;
    s->m = 2; s->n = 3; s->r = 3;
    s->event_mode_used = eventModeUsed;
    defaults(s);
    return s;
}
EXPORT void fmi3FreeInstance(void *c) { free(c); }
EXPORT int fmi3EnterConfigurationMode(void *c) { return ((Model *)c)->initialised ? ERROR : OK; }
EXPORT int fmi3ExitConfigurationMode(void *c) { return OK; }
EXPORT int fmi3EnterInitializationMode(void *c, bool tolDef, double tol, double t0, bool stopDef, double stop) {
    ((Model *)c)->time = t0;
    return OK;
}
EXPORT int fmi3ExitInitializationMode(void *c) {
    Model *s = c;
    memcpy(s->x, s->x0, sizeof s->x);
    s->initialised = 1;
    s->in_event = s->event_mode_used;
    return OK;
}
EXPORT int fmi3Terminate(void *c) { return OK; }
EXPORT int fmi3Reset(void *c) {
    Model *s = c;
    s->m = 2; s->n = 3; s->r = 3; s->initialised = 0; s->g = 0.0;
    defaults(s);
    return OK;
}

EXPORT int fmi3GetUInt64(void *c, const uint32_t vr[], size_t n, uint64_t v[], size_t nv) {
    Model *s = c;
    if (nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 1) v[i] = s->m;
        else if (vr[i] == 2) v[i] = s->n;
        else if (vr[i] == 3) v[i] = s->r;
        else return ERROR;
    }
    return OK;
}
EXPORT int fmi3SetUInt64(void *c, const uint32_t vr[], size_t n, const uint64_t v[], size_t nv) {
    Model *s = c;
    if (s->initialised || nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (v[i] < 1 || v[i] > MAXD) return ERROR;
        if (vr[i] == 1) s->m = v[i];
        else if (vr[i] == 2) s->n = v[i];
        else if (vr[i] == 3) s->r = v[i];
        else return ERROR;
    }
    defaults(s);
    return OK;
}

EXPORT int fmi3GetFloat64(void *c, const uint32_t vr[], size_t n, double v[], size_t nv) {
    Model *s = c;
    size_t at = 0;
    for (size_t i = 0; i < n; i++) {
        size_t count;
        if (vr[i] == 0) { count = 1; if (at + count > nv) return ERROR; v[at] = s->time; }
        else if (vr[i] == 14) { count = 2; if (at + count > nv) return ERROR; v[at] = s->x[0]; v[at + 1] = s->time; }
        else if (vr[i] == 10 || vr[i] == 13) {
            double y[MAXD];
            outputs(s, y);
            if (vr[i] == 10) {
                count = s->r;
                if (at + count > nv) return ERROR;
                memcpy(v + at, y, count * sizeof(double));
            } else {
                count = 1;
                if (at + count > nv) return ERROR;
                v[at] = 0.0;
                for (uint64_t l = 0; l < s->r; l++) v[at] += y[l];
            }
        } else {
            double *p = array(s, vr[i], &count);
            if (!p || at + count > nv) return ERROR;
            memcpy(v + at, p, count * sizeof(double));
        }
        at += count;
    }
    return at == nv ? OK : ERROR;
}
EXPORT int fmi3SetFloat64(void *c, const uint32_t vr[], size_t n, const double v[], size_t nv) {
    Model *s = c;
    size_t at = 0;
    for (size_t i = 0; i < n; i++) {
        size_t count;
        double *p = array(s, vr[i], &count);
        if (!p || vr[i] == 11 || vr[i] == 23 || vr[i] == 24 || at + count > nv) return ERROR;
        memcpy(p, v + at, count * sizeof(double));
        at += count;
    }
    return at == nv ? OK : ERROR;
}

static double sum_of_y(Model *s) {
    double y[MAXD], sum = 0.0;
    outputs(s, y);
    for (uint64_t l = 0; l < s->r; l++) sum += y[l];
    return sum;
}

EXPORT int fmi3GetFloat32(void *c, const uint32_t vr[], size_t n, float v[], size_t nv) {
    Model *s = c;
    if (nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 19) v[i] = (float)sum_of_y(s) + s->k32;
        else if (vr[i] == 22) v[i] = s->k32;
        else return ERROR;
    }
    return OK;
}
EXPORT int fmi3SetFloat32(void *c, const uint32_t vr[], size_t n, const float v[], size_t nv) {
    if (nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 22) return ERROR;
        ((Model *)c)->k32 = v[i];
    }
    return OK;
}
EXPORT int fmi3GetString(void *c, const uint32_t vr[], size_t n, const char *v[], size_t nv) {
    Model *s = c;
    if (nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 15) v[i] = s->label;
        else if (vr[i] == 16) {
            strcpy(s->greeting, "hello ");
            strcat(s->greeting, s->label);
            v[i] = s->greeting;
        } else return ERROR;
    }
    return OK;
}
EXPORT int fmi3SetString(void *c, const uint32_t vr[], size_t n, const char *const v[], size_t nv) {
    Model *s = c;
    if (nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 15 || !v[i] || strlen(v[i]) >= MAXTEXT) return ERROR;
        strcpy(s->label, v[i]);
    }
    return OK;
}
EXPORT int fmi3GetBinary(void *c, const uint32_t vr[], size_t n, size_t sizes[], const uint8_t *v[], size_t nv) {
    Model *s = c;
    if (nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 17) v[i] = s->blob;
        else if (vr[i] == 18) {
            for (size_t k = 0; k < s->blob_size; k++) s->blob_out[k] = s->blob[s->blob_size - 1 - k];
            v[i] = s->blob_out;
        } else return ERROR;
        sizes[i] = s->blob_size;
    }
    return OK;
}
EXPORT int fmi3SetBinary(void *c, const uint32_t vr[], size_t n, const size_t sizes[], const uint8_t *const v[],
                         size_t nv) {
    Model *s = c;
    if (nv != n) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 17 || sizes[i] > MAXBLOB) return ERROR;
        if (sizes[i]) memcpy(s->blob, v[i], sizes[i]);
        s->blob_size = sizes[i];
    }
    return OK;
}

EXPORT int fmi3DoStep(void *c, double t, double h, bool noSetPrior, bool *eventNeeded, bool *terminate,
                      bool *earlyReturn, double *lastT) {
    Model *s = c;
    double dt = h / 10.0, dx[MAXD];
    if (s->in_event) return ERROR;
    for (int k = 0; k < 10; k++) {
        for (uint64_t i = 0; i < s->n; i++) {
            double d = s->g;
            for (uint64_t j = 0; j < s->n; j++) d += s->A[i * s->n + j] * s->x[j];
            for (uint64_t q = 0; q < s->m; q++) d += s->B[i * s->m + q] * s->u[q];
            dx[i] = d;
        }
        for (uint64_t i = 0; i < s->n; i++) s->x[i] += dt * dx[i];
    }
    s->time = t + h;
    *eventNeeded = false;
    *terminate = false;
    *earlyReturn = false;
    *lastT = s->time;
    return OK;
}

EXPORT int fmi3GetFMUState(void *c, void **st) {
    if (!*st) *st = malloc(sizeof(Model));
    if (!*st) return ERROR;
    memcpy(*st, c, sizeof(Model));
    return OK;
}
EXPORT int fmi3SetFMUState(void *c, void *st) { memcpy(c, st, sizeof(Model)); return OK; }
EXPORT int fmi3FreeFMUState(void *c, void **st) { free(*st); *st = NULL; return OK; }
EXPORT int fmi3SerializedFMUStateSize(void *c, void *st, size_t *n) { *n = sizeof(Model); return OK; }
EXPORT int fmi3SerializeFMUState(void *c, void *st, uint8_t b[], size_t n) {
    if (n != sizeof(Model)) return ERROR;
    memcpy(b, st, n);
    return OK;
}
EXPORT int fmi3DeserializeFMUState(void *c, const uint8_t b[], size_t n, void **st) {
    if (n != sizeof(Model)) return ERROR;
    *st = malloc(n);
    if (!*st) return ERROR;
    memcpy(*st, b, n);
    return OK;
}

EXPORT int fmi3EnterEventMode(void *c) {
    Model *s = c;
    if (!s->event_mode_used || !s->initialised) return ERROR;
    s->in_event = true;
    return OK;
}
EXPORT int fmi3EnterStepMode(void *c) {
    Model *s = c;
    if (!s->in_event) return ERROR;
    s->in_event = false;
    return OK;
}
EXPORT int fmi3SetClock(void *c, const uint32_t vr[], size_t n, const bool v[]) {
    Model *s = c;
    if (!s->in_event) return ERROR;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 20) return ERROR;
        s->tick_active = v[i];
    }
    return OK;
}
EXPORT int fmi3UpdateDiscreteStates(void *c, bool *needUpdate, bool *terminate, bool *nominalsChanged,
                                    bool *valuesChanged, bool *nextDefined, double *next) {
    Model *s = c;
    if (!s->in_event) return ERROR;
    if (s->tick_active) { /* the clocked partition, once per tick */
        s->held = sum_of_y(s);
        s->ticks += 1.0;
        s->tick_active = false;
    }
    *needUpdate = *terminate = *nominalsChanged = *valuesChanged = *nextDefined = false;
    *next = 0.0;
    return OK;
}

/* The rest of the standard, never called here. */
#define STUB(name) EXPORT int name(void) { return ERROR; }
STUB(fmi3ActivateModelPartition) STUB(fmi3EnterContinuousTimeMode)
STUB(fmi3CompletedIntegratorStep) STUB(fmi3SetTime) STUB(fmi3SetContinuousStates)
STUB(fmi3GetContinuousStateDerivatives) STUB(fmi3GetEventIndicators) STUB(fmi3GetContinuousStates)
STUB(fmi3GetNominalsOfContinuousStates) STUB(fmi3GetNumberOfEventIndicators) STUB(fmi3GetNumberOfContinuousStates)
STUB(fmi3InstantiateModelExchange)
STUB(fmi3EvaluateDiscreteStates) STUB(fmi3GetAdjointDerivative)
STUB(fmi3GetBoolean) STUB(fmi3GetClock) STUB(fmi3GetDirectionalDerivative)
STUB(fmi3GetInt16) STUB(fmi3GetInt32) STUB(fmi3GetInt64) STUB(fmi3GetInt8)
STUB(fmi3GetIntervalDecimal) STUB(fmi3GetIntervalFraction) STUB(fmi3GetNumberOfVariableDependencies)
STUB(fmi3GetOutputDerivatives) STUB(fmi3GetShiftDecimal) STUB(fmi3GetShiftFraction) 
STUB(fmi3GetUInt16) STUB(fmi3GetUInt32) STUB(fmi3GetUInt8) STUB(fmi3GetVariableDependencies)
STUB(fmi3InstantiateScheduledExecution) STUB(fmi3SetBoolean) 
STUB(fmi3SetInt16) STUB(fmi3SetInt32) STUB(fmi3SetInt64) STUB(fmi3SetInt8)
STUB(fmi3SetIntervalDecimal) STUB(fmi3SetIntervalFraction) STUB(fmi3SetShiftDecimal) STUB(fmi3SetShiftFraction)
STUB(fmi3SetUInt16) STUB(fmi3SetUInt32) STUB(fmi3SetUInt8)
