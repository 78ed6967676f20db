/* Three small FMI 2.0 co-simulation FMUs for benchmarks/inprocess.py, one source compiled once
 * per model (-DMODEL=...): the system the in-process benchmark runs beside ECOS.
 *
 *   MODEL 1, Dahlquist:   der(x) = -k x (x(0) = 1, k = 1), forward Euler over the step;
 *   MODEL 2, Feedthrough: y = u, at once (a direct feedthrough);
 *   MODEL 3, VanDerPol:   der(x0) = x1, der(x1) = mu (1 - x0^2) x1 - x0 (x0(0) = 2, mu = 1),
 *                         forward Euler in 10 substeps per step.
 *
 * Every variable is a Real at value reference 0..N-1 (see benchmarks/_small_fmus.py). The
 * state can be saved and restored (fmi2Get/SetFMUstate) but not serialised.
 */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#if MODEL == 1
#define N_VARS 2 /* k, x */
static const double START[N_VARS] = {1.0, 1.0};
static void step(double *r, double h) { r[1] += h * (-r[0] * r[1]); }
static void settle(double *r) { (void)r; }
#elif MODEL == 2
#define N_VARS 2 /* u, y */
static const double START[N_VARS] = {0.0, 0.0};
static void step(double *r, double h) { (void)r; (void)h; }
static void settle(double *r) { r[1] = r[0]; }
#elif MODEL == 3
#define N_VARS 3 /* mu, x0, x1 */
static const double START[N_VARS] = {1.0, 2.0, 0.0};
static void step(double *r, double h) {
    double dt = h / 10.0;
    for (int i = 0; i < 10; i++) {
        double x0 = r[1], x1 = r[2];
        r[1] = x0 + dt * x1;
        r[2] = x1 + dt * (r[0] * (1.0 - x0 * x0) * x1 - x0);
    }
}
static void settle(double *r) { (void)r; }
#else
#error "MODEL must be 1, 2 or 3"
#endif

typedef struct { double r[N_VARS]; } Instance;

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
    if (inst) memcpy(inst->r, START, sizeof START);
    return inst;
}
FMI2_Export void fmi2FreeInstance(fmi2Component c) { free(c); }
FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                                           fmi2Boolean stop_defined, fmi2Real stop) {
    (void)c; (void)tol_defined; (void)tol; (void)start; (void)stop_defined; (void)stop;
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component c) { settle(((Instance *)c)->r); return fmi2OK; }
FMI2_Export fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
FMI2_Export fmi2Status fmi2Reset(fmi2Component c) {
    memcpy(((Instance *)c)->r, START, sizeof START);
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Instance *inst = c;
    settle(inst->r);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS) return fmi2Error;
        value[i] = inst->r[vr[i]];
    }
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Instance *inst = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS) return fmi2Error;
        inst->r[vr[i]] = value[i];
    }
    return fmi2OK;
}
FMI2_Export fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t0, fmi2Real h, fmi2Boolean no_prior) {
    (void)t0; (void)no_prior;
    step(((Instance *)c)->r, h);
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
FMI2_Export fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[])
    REFUSE(vr, n, v)
FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[])
    REFUSE(vr, n, v)
FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[])
    REFUSE(vr, n, v)
FMI2_Export fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[])
    REFUSE(vr, n, v)
FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[])
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
