/* A minimal FMI 2.0 co-simulation importer with no Python in its process: dlopen the
 * FMU's binary, instantiate, set the gateway address, doStep N times with the input
 * y = 2t + 1, and print "t,u" after each step. Used by the bridge FMU tests.
 * usage: importer BINARY.so GUID RESOURCES_URI SERVER STEPS H
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String cat, fmi2String fmt, ...) {
    va_list ap;
    (void)env;
    va_start(ap, fmt);
    fprintf(stderr, "[%s %d %s] ", name, (int)status, cat);
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

#define LOAD(T, f) T f = (T)dlsym(lib, #f); if (!f) { fprintf(stderr, "missing %s\n", #f); return 2; }

int main(int argc, char **argv) {
    if (argc != 7) { fprintf(stderr, "usage: importer SO GUID RESOURCES SERVER STEPS H\n"); return 2; }
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 2; }
    LOAD(fmi2InstantiateTYPE *, fmi2Instantiate)
    LOAD(fmi2SetupExperimentTYPE *, fmi2SetupExperiment)
    LOAD(fmi2EnterInitializationModeTYPE *, fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationModeTYPE *, fmi2ExitInitializationMode)
    LOAD(fmi2SetStringTYPE *, fmi2SetString)
    LOAD(fmi2SetRealTYPE *, fmi2SetReal)
    LOAD(fmi2GetRealTYPE *, fmi2GetReal)
    LOAD(fmi2DoStepTYPE *, fmi2DoStep)
    LOAD(fmi2TerminateTYPE *, fmi2Terminate)
    LOAD(fmi2FreeInstanceTYPE *, fmi2FreeInstance)
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("importer", fmi2CoSimulation, argv[2], argv[3], &cb, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "instantiate failed\n"); return 3; }
    int steps = atoi(argv[5]);
    double h = atof(argv[6]);
    const fmi2ValueReference vr_y = 0, vr_u = 1, vr_server = 2;
    fmi2String server = argv[4];
    if (fmi2SetString(c, &vr_server, 1, &server) != fmi2OK) return 3;
    fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    fmi2EnterInitializationMode(c);
    if (fmi2ExitInitializationMode(c) != fmi2OK) { fprintf(stderr, "attach failed\n"); return 4; }
    for (int k = 0; k < steps; k++) {
        double t = k * h, y = 2 * t + 1, u;
        fmi2SetReal(c, &vr_y, 1, &y);
        if (fmi2DoStep(c, t, h, fmi2True) != fmi2OK) { fprintf(stderr, "doStep failed at %d\n", k); return 5; }
        fmi2GetReal(c, &vr_u, 1, &u);
        printf("%.17g,%.17g\n", t + h, u);
    }
    fmi2Terminate(c);
    fmi2FreeInstance(c);
    dlclose(lib);
    return 0;
}
