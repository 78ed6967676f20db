/* One mass of the accuracy benchmark's oscillators, as a native FMI 2.0 co-simulation FMU
 * (built by benchmarks/accuracy.py's build_mass_fmu; the same model as the pythonfmu one in
 * benchmarks/_mass_fmu.py, which cannot interpolate its inputs).
 *
 * The mass m hangs on a spring k and a damper c to the wall. It takes a force F from outside,
 * or holds a coupling spring itself: it takes the displacement xl (spring kl, the neighbour on
 * its left) or xr (spring kr, on its right) and gives back the force that spring puts on the
 * neighbour, Fl = kl (x - xl) or Fr = kr (x - xr). It may be struck by a half-sine pulse.
 *
 * It integrates its own ODE finely (RK4, at least `substeps` per step and at most `max_dt`
 * long), so that the error the benchmark measures is the coupling's. Its Real inputs follow
 * the polynomial the master gives with fmi2SetRealInputDerivatives (orders 1 to 3, the Taylor
 * coefficients at the step's start: canInterpolateInputs); without derivatives they are held.
 * Its state can be saved, restored and serialised (the master's rollback and checkpoints).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define PI 3.14159265358979323846

enum { P_M, P_K, P_C, P_KL, P_KR, P_AT, P_WIDTH, P_PULSE, P_SUBSTEPS, P_MAXDT, N_PARAMS };
enum { VR_F = N_PARAMS, VR_XL, VR_XR, VR_X, VR_V, VR_FL, VR_FR, N_VARS };
#define N_INPUTS 3
#define MAX_ORDER 3

typedef struct {
    double p[N_PARAMS];
    double u[N_INPUTS];              /* the inputs at the step's start */
    double du[N_INPUTS][MAX_ORDER];  /* their derivatives there, orders 1..3 */
    double x, v, t;
} Model;

typedef struct {
    Model m;
    fmi2CallbackFunctions cb;
    fmi2String name;
} Instance;

static void say(Instance *inst, fmi2Status status, const char *msg) {
    if (inst->cb.logger) inst->cb.logger(inst->cb.componentEnvironment, inst->name, status, "error", msg);
}

/* Input i at tau seconds after the step's start. */
static double input_at(const Model *m, int i, double tau) {
    const double *d = m->du[i];
    return m->u[i] + tau * (d[0] + tau * (d[1] / 2.0 + tau * d[2] / 6.0));
}

static double accel(const Model *m, double t0, double s, double x, double v) {
    const double *p = m->p;
    double kick = 0.0, tau = s - t0;
    if (p[P_PULSE] != 0.0 && p[P_AT] <= s && s <= p[P_AT] + p[P_WIDTH])
        kick = p[P_PULSE] * sin(PI * (s - p[P_AT]) / p[P_WIDTH]);
    double f = input_at(m, 0, tau), xl = input_at(m, 1, tau), xr = input_at(m, 2, tau);
    return (-p[P_K] * x - p[P_C] * v + f + kick - p[P_KL] * (x - xl) - p[P_KR] * (x - xr)) / p[P_M];
}

FMI2_Export const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
FMI2_Export const char *fmi2GetVersion(void) { return fmi2Version; }
FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi2OK;
}

FMI2_Export fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                                          const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                          fmi2Boolean logging) {
    (void)guid; (void)resources; (void)visible; (void)logging;
    if (type != fmi2CoSimulation) return NULL;
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    if (functions) inst->cb = *functions;
    inst->name = name;
    double defaults[N_PARAMS] = {1.0, 10.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 20.0, 1e-4};
    memcpy(inst->m.p, defaults, sizeof defaults);
    return inst;
}

FMI2_Export void fmi2FreeInstance(fmi2Component c) { free(c); }

FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                                           fmi2Boolean stop_defined, fmi2Real stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    ((Instance *)c)->m.t = start;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
FMI2_Export fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
FMI2_Export fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2Error; }

static double value_of(const Model *m, fmi2ValueReference vr) {
    if (vr < N_PARAMS) return m->p[vr];
    switch (vr) {
    case VR_F: case VR_XL: case VR_XR: return m->u[vr - VR_F];
    case VR_X: return m->x;
    case VR_V: return m->v;
    case VR_FL: return m->p[P_KL] * (m->x - m->u[1]);
    default: return m->p[P_KR] * (m->x - m->u[2]);
    }
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Instance *inst = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS) { say(inst, fmi2Error, "unknown value reference"); return fmi2Error; }
        value[i] = value_of(&inst->m, vr[i]);
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Instance *inst = c;
    Model *m = &inst->m;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < N_PARAMS) m->p[vr[i]] = value[i];
        else if (vr[i] <= VR_XR) {
            m->u[vr[i] - VR_F] = value[i];
            memset(m->du[vr[i] - VR_F], 0, sizeof m->du[0]);  /* a value without derivatives is held */
        }
        else if (vr[i] == VR_X) m->x = value[i];
        else if (vr[i] == VR_V) m->v = value[i];
        else { say(inst, fmi2Error, "this variable cannot be set"); return fmi2Error; }
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                   const fmi2Integer order[], const fmi2Real value[]) {
    Instance *inst = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < VR_F || vr[i] > VR_XR || order[i] < 1 || order[i] > MAX_ORDER) {
            say(inst, fmi2Error, "input derivatives: an input of orders 1 to 3 only");
            return fmi2Error;
        }
        inst->m.du[vr[i] - VR_F][order[i] - 1] = value[i];
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t0, fmi2Real h, fmi2Boolean no_prior) {
    (void)no_prior;
    Model *m = &((Instance *)c)->m;
    int n = (int)m->p[P_SUBSTEPS];
    int fine = (int)ceil(h / m->p[P_MAXDT]);
    if (fine > n) n = fine;
    if (n < 1) n = 1;
    double dt = h / n, x = m->x, v = m->v;
    for (int i = 0; i < n; i++) {
        double s = t0 + i * dt;
        double a1 = accel(m, t0, s, x, v);
        double x2 = x + 0.5 * dt * v, v2 = v + 0.5 * dt * a1;
        double a2 = accel(m, t0, s + 0.5 * dt, x2, v2);
        double x3 = x + 0.5 * dt * v2, v3 = v + 0.5 * dt * a2;
        double a3 = accel(m, t0, s + 0.5 * dt, x3, v3);
        double x4 = x + dt * v3, v4 = v + dt * a3;
        double a4 = accel(m, t0, s + dt, x4, v4);
        x += dt / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4);
        v += dt / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
    }
    m->x = x;
    m->v = v;
    m->t = t0 + h;
    /* The inputs at the step's end (which the outputs Fl and Fr read), held from here. */
    for (int i = 0; i < N_INPUTS; i++) {
        m->u[i] = input_at(m, i, h);
        memset(m->du[i], 0, sizeof m->du[i]);
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Model *copy = *state ? (Model *)*state : malloc(sizeof *copy);
    if (!copy) return fmi2Error;
    *copy = ((Instance *)c)->m;
    *state = copy;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    if (!state) return fmi2Error;
    ((Instance *)c)->m = *(Model *)state;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    (void)c;
    free(*state);
    *state = NULL;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    (void)c; (void)state;
    *size = sizeof(Model);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    (void)c;
    if (size < sizeof(Model)) return fmi2Error;
    memcpy(bytes, state, sizeof(Model));
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                               fmi2FMUstate *state) {
    (void)c;
    if (size != sizeof(Model)) return fmi2Error;
    Model *copy = malloc(sizeof *copy);
    if (!copy) return fmi2Error;
    memcpy(copy, bytes, sizeof *copy);
    *state = copy;
    return fmi2OK;
}

/* What this FMU does not do: Model Exchange, integers, booleans, strings, output derivatives. */
FMI2_Export fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
FMI2_Export fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
FMI2_Export fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
FMI2_Export fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                                    const fmi2ValueReference z[], size_t nz, const fmi2Real du[],
                                                    fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)du; (void)dz; return fmi2Error;
}
FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                    const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)order; (void)value; return n ? fmi2Error : fmi2OK;
}
FMI2_Export fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
FMI2_Export fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
