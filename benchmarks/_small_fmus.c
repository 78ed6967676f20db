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
 * The models are in benchmarks/_small_models.h. Value references (see benchmarks/_small_fmus.py): Reals 0..N_REAL-1, Integers from 100,
 * Booleans from 200. The state can be saved and restored (fmi2Get/SetFMUstate) but not
 * serialised.
 */
#include "fmi2Functions.h"
#include "_small_models.h"

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
