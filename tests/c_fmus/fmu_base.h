/* A minimal FMI 2.0 co-simulation slave for the engine's tests: every fmi2 function of the
   co-simulation interface, over one model of a few Real, Integer, Boolean and String
   variables indexed by value reference (an Enumeration is an Integer here).

   A model source defines N_REAL, N_INTEGER, N_BOOLEAN, N_STRING (each >= 1), then includes
   this file, then defines
       static void model_start(Model *m);                          the start values
       static void model_outputs(Model *m);                        outputs from the rest
       static fmi2Status model_step(Model *m, double t, double h);   one fmi2DoStep
   (model_outputs is called by fmi2ExitInitializationMode; model_step calls it itself.)
   model_step may set m->terminated = fmi2True and return fmi2Discard to end the simulation.
   The strings fmi2GetString gives are valid only until the next call to the instance, as
   FMI 2.0 allows: the next call overwrites them with "stale" (a master must copy them).
   Built with the FMI 2.0 headers (fmpy ships them in fmpy/c-code). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define STRING_SIZE 64

typedef struct {
    fmi2Real r[N_REAL];
    fmi2Integer i[N_INTEGER];
    fmi2Boolean b[N_BOOLEAN];
    char s[N_STRING][STRING_SIZE];
    char s_out[N_STRING][STRING_SIZE];  /* what fmi2GetString gave, until the next call */
    double time;
    fmi2Boolean terminated;
    fmi2CallbackFunctions cb;
    char name[STRING_SIZE];
} Model;

static void model_start(Model *m);
static void model_outputs(Model *m);
static fmi2Status model_step(Model *m, double t, double h);

/* text is passed as the format, with no arguments (a master's logger may not format): no '%' in it */
static void log_text(Model *m, fmi2Status status, const char *text) {
    if (m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, status, "logAll", text);
}

static void spoil_strings(Model *m) {
    for (int k = 0; k < N_STRING; k++) snprintf(m->s_out[k], STRING_SIZE, "stale");
}

/* every get and set: spoil the strings given before, check the value references */
#define CHECK_VRS(N) do { spoil_strings(m); for (size_t k = 0; k < nvr; k++) if (vr[k] >= (N)) { \
    log_text(m, fmi2Error, "value reference out of range"); return fmi2Error; } } while (0)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    (void)guid; (void)location; (void)visible; (void)logging;
    if (type != fmi2CoSimulation) return NULL;
    Model *m = (Model *)calloc(1, sizeof(Model));
    if (!m) return NULL;
    m->cb = *cb;
    snprintf(m->name, STRING_SIZE, "%s", name ? name : "");
    model_start(m);
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_on, fmi2Real tol, fmi2Real t0,
                               fmi2Boolean stop_on, fmi2Real t1) {
    (void)tol_on; (void)tol; (void)stop_on; (void)t1;
    ((Model *)c)->time = t0;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { model_outputs((Model *)c); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) {
    Model *m = (Model *)c;
    model_start(m);
    m->time = 0; m->terminated = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_REAL);
    for (size_t k = 0; k < nvr; k++) v[k] = m->r[vr[k]];
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_INTEGER);
    for (size_t k = 0; k < nvr; k++) v[k] = m->i[vr[k]];
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_BOOLEAN);
    for (size_t k = 0; k < nvr; k++) v[k] = m->b[vr[k]];
    return fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_STRING);
    for (size_t k = 0; k < nvr; k++) {
        memcpy(m->s_out[vr[k]], m->s[vr[k]], STRING_SIZE);
        v[k] = m->s_out[vr[k]];
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_REAL);
    for (size_t k = 0; k < nvr; k++) m->r[vr[k]] = v[k];
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_INTEGER);
    for (size_t k = 0; k < nvr; k++) m->i[vr[k]] = v[k];
    return fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_BOOLEAN);
    for (size_t k = 0; k < nvr; k++) m->b[vr[k]] = v[k] ? fmi2True : fmi2False;
    return fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String v[]) {
    Model *m = (Model *)c; CHECK_VRS(N_STRING);
    for (size_t k = 0; k < nvr; k++) {
        if (!v[k]) { log_text(m, fmi2Error, "fmi2SetString: NULL string"); return fmi2Error; }
        snprintf(m->s[vr[k]], STRING_SIZE, "%s", v[k]);
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Model *m = (Model *)c;
    (void)no_prior;
    spoil_strings(m);
    if (m->terminated) { log_text(m, fmi2Error, "fmi2DoStep after a termination request"); return fmi2Error; }
    fmi2Status status = model_step(m, t, h);
    if (status <= fmi2Warning) m->time = t + h;
    return status;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    if (s != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = ((Model *)c)->time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    if (s != fmi2Terminated) return fmi2Discard;
    *v = ((Model *)c)->terminated;
    return fmi2OK;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}

/* not supported (the model description says so: no FMU state, no directional derivatives) */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n; return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)b; (void)n; (void)s; return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[],
                                        fmi2Real df[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)df; return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)v; return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real v[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)v; return fmi2Error;
}
