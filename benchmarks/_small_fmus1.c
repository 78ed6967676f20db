/* The small models of benchmarks/_small_models.h as FMI 1.0 co-simulation FMUs (-DMODEL=...,
 * -DMODEL_IDENTIFIER=...): every function named <modelIdentifier>_fmi..., as FMI 1.0 has them.
 * The start inputs are set before fmiInitializeSlave, which computes the outputs from them.
 * No state get/set (FMI 1.0 has none). */
#include <stddef.h> /* fmpy's fmi1Functions.h uses size_t without it */
#include "fmi1Functions.h"
#include "_small_models.h"

#define CAT2(a, b) a##_##b
#define CAT(a, b) CAT2(a, b)
#define F(name) CAT(MODEL_IDENTIFIER, name)
#define EXPORT __attribute__((visibility("default")))

EXPORT const char *F(fmiGetTypesPlatform)(void) { return "standard32"; }
EXPORT const char *F(fmiGetVersion)(void) { return "1.0"; }
EXPORT fmi1Status F(fmiSetDebugLogging)(fmi1Component c, fmi1Boolean on) {
    (void)c; (void)on;
    return fmi1OK;
}
EXPORT fmi1Component F(fmiInstantiateSlave)(fmi1String name, fmi1String guid, fmi1String location,
                                            fmi1String mime, fmi1Real timeout, fmi1Boolean visible,
                                            fmi1Boolean interactive, fmi1CallbackFunctions functions,
                                            fmi1Boolean logging) {
    (void)name; (void)guid; (void)location; (void)mime; (void)timeout; (void)visible; (void)interactive;
    (void)functions; (void)logging;
    Instance *inst = calloc(1, sizeof *inst);
    if (inst) start(inst);
    return inst;
}
EXPORT fmi1Status F(fmiInitializeSlave)(fmi1Component c, fmi1Real t0, fmi1Boolean stop_defined, fmi1Real stop) {
    (void)t0; (void)stop_defined; (void)stop;
    settle(c);
    return fmi1OK;
}
EXPORT fmi1Status F(fmiTerminateSlave)(fmi1Component c) { (void)c; return fmi1OK; }
EXPORT fmi1Status F(fmiResetSlave)(fmi1Component c) {
    start(c);
    return fmi1OK;
}
EXPORT void F(fmiFreeSlaveInstance)(fmi1Component c) { free(c); }

#define ACCESS1(Type, ctype, array, first, count)                                                      \
    EXPORT fmi1Status F(fmiGet##Type)(fmi1Component c, const fmi1ValueReference vr[], size_t n,       \
                                      ctype value[]) {                                                 \
        Instance *inst = c;                                                                            \
        on_get(inst);                                                                                  \
        for (size_t k = 0; k < n; k++) {                                                               \
            if (vr[k] < (first) || vr[k] >= (first) + (count)) return fmi1Error;                       \
            value[k] = (ctype)inst->array[vr[k] - (first)];                                            \
        }                                                                                              \
        return fmi1OK;                                                                                 \
    }                                                                                                  \
    EXPORT fmi1Status F(fmiSet##Type)(fmi1Component c, const fmi1ValueReference vr[], size_t n,       \
                                      const ctype value[]) {                                           \
        Instance *inst = c;                                                                            \
        for (size_t k = 0; k < n; k++) {                                                               \
            if (vr[k] < (first) || vr[k] >= (first) + (count)) return fmi1Error;                       \
            inst->array[vr[k] - (first)] = value[k];                                                   \
        }                                                                                              \
        return fmi1OK;                                                                                 \
    }
ACCESS1(Real, fmi1Real, r, 0u, N_REAL)
ACCESS1(Integer, fmi1Integer, i, (unsigned)INT0, N_INT)
ACCESS1(Boolean, fmi1Boolean, b, (unsigned)BOOL0, N_BOOL)

EXPORT fmi1Status F(fmiDoStep)(fmi1Component c, fmi1Real t, fmi1Real h, fmi1Boolean new_step) {
    (void)t; (void)new_step;
    step(c, h);
    return fmi1OK;
}
#define REFUSE1(...) { (void)c; return fmi1Error; }
EXPORT fmi1Status F(fmiGetString)(fmi1Component c, const fmi1ValueReference vr[], size_t n, fmi1String v[])
    REFUSE1(vr, n, v)
EXPORT fmi1Status F(fmiSetString)(fmi1Component c, const fmi1ValueReference vr[], size_t n, const fmi1String v[])
    REFUSE1(vr, n, v)
EXPORT fmi1Status F(fmiSetRealInputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t n,
                                               const fmi1Integer order[], const fmi1Real v[]) REFUSE1(vr, n, order, v)
EXPORT fmi1Status F(fmiGetRealOutputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t n,
                                                const fmi1Integer order[], fmi1Real v[]) REFUSE1(vr, n, order, v)
EXPORT fmi1Status F(fmiCancelStep)(fmi1Component c) REFUSE1()
EXPORT fmi1Status F(fmiGetStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Status *v) REFUSE1(s, v)
EXPORT fmi1Status F(fmiGetRealStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Real *v) REFUSE1(s, v)
EXPORT fmi1Status F(fmiGetIntegerStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Integer *v) REFUSE1(s, v)
EXPORT fmi1Status F(fmiGetBooleanStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Boolean *v) REFUSE1(s, v)
EXPORT fmi1Status F(fmiGetStringStatus)(fmi1Component c, const fmi1StatusKind s, fmi1String *v) REFUSE1(s, v)
