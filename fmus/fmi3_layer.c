/*
 * The FMI 3.0 co-simulation layer (Linux): binaries/x86_64-linux/<model>.so of the project's FMI 3.0 units, in
 * front of the same FMI 2.0 stack as the FMI 2.0 units: the FMU's loader (fmu_loader.c, beside it as FMI2_LOADER),
 * the lean binding (pmsm-binding.so) and pythonfmu's library (pythonfmu-export.so). Why and what: fmus/README.md,
 * "FMI 3.0".
 *
 * Every fmi3 function of co-simulation is one or two fmi2 calls of the loader (dlopen'ed RTLD_LOCAL, once per
 * process, at the first fmi3InstantiateCoSimulation). fmi2GetReal, fmi2SetReal and fmi2DoStep, the calls of every
 * step, which the loader only forwards to the binding, are the binding's own, called directly and without the
 * binding's look-up of the instance, which this layer has made (its own, at every call) and whose FMI 2.0 instance it
 * frees only in fmi3FreeInstance: the loader gives their addresses once the binding is loaded (pmsm_fmu_known; else
 * pmsm_fmu_forwarded, with the look-up), and each instance keeps them beside its FMI 2.0 instance (direct_calls), one
 * hop and one look-up less a call than through the loader, with the same arguments and answers:
 *
 *   fmi3InstantiateCoSimulation  fmi2Instantiate (fmi2CoSimulation; the instantiation token as the GUID; the
 *                                resource folder as a file URI), with an fmi2 logger that formats the message and
 *                                hands it to the host's fmi3 logMessage callback;
 *   fmi3EnterInitializationMode  fmi2SetupExperiment, then fmi2EnterInitializationMode;
 *   fmi3ExitInitializationMode, fmi3Terminate, fmi3Reset, fmi3FreeInstance, fmi3SetDebugLogging: their fmi2 twins;
 *   fmi3Get/SetFloat64           fmi2Get/SetReal (pythonfmu's value references are unique across types); the
 *                                independent variable `time` (TIME_REFERENCE, which FMI 3.0 requires and FMI 2.0
 *                                has not) is answered here: the start time, then the end of the last step (after
 *                                an FMU state is restored: the stack's fmi2LastSuccessfulTime); it cannot be set;
 *   fmi3Get/SetInt32             fmi2Get/SetInteger; fmi3Get/SetBoolean fmi2Get/SetBoolean (bool <-> int);
 *   fmi3Get/SetString            fmi2Get/SetString;
 *   fmi3DoStep                   fmi2DoStep: eventHandlingNeeded and earlyReturn false, lastSuccessfulTime the end
 *                                of the step (after a discarded step the stack's fmi2LastSuccessfulTime, and
 *                                terminateSimulation its fmi2Terminated; fmi2Fatal terminates);
 *   the FMU state: fmi3Get/Set/FreeFMUState, fmi3SerializedFMUStateSize, fmi3Serialize/DeserializeFMUState.
 *
 * A status of FMI 2.0 is the FMI 3.0 one of the same name (fmi2Pending, which co-simulation here never returns,
 * is fmi3Error). The FMI 2.0 stack keeps its checks (the state machine, non-finite inputs, a communication point
 * that does not continue the last step, a step too long: fmus/README.md, "Misuse"): their statuses and log lines
 * reach the FMI 3.0 host unchanged. Every other function of the FMI 3.0 API is exported and answers fmi3Error with
 * one log line (the model has no variable of that type, no event mode, no clock, no model exchange, ...); the
 * other instantiate functions log and return NULL.
 *
 * The sample clock (fmus/README.md, "The sample clock"): a controller's unit has resources/CLOCK_FILE and its model
 * description a periodic input Clock and hasEventMode="true" (the others: "false", and eventModeUsed is refused).
 * Instantiated with eventModeUsed, the stack steps only at the clock's ticks: fmi3EnterEventMode, fmi3SetClock,
 * fmi3UpdateDiscreteStates (fmi2DoStep of one interval from the tick: the sample there), fmi3EnterStepMode; then
 * fmi3DoStep moves the time within the interval, the outputs held, and refuses to pass a tick not set. Without
 * eventModeUsed the clock is never set and fmi3DoStep is fmi2DoStep: the unit samples at its own period.
 *
 * pmsm_fmu_fast_calls, pmsm_fmu_compiled_calls and pmsm_fmu_pulls (the lean binding's counters, fmus/README.md)
 * take an fmi3 instance and answer its FMI 2.0 instance's.
 *
 * An instance this layer did not make, or has freed (NULL, a stale pointer), gets fmi3Error from every function
 * without being touched (fmi3FreeInstance of it does nothing): the instances made are in a table, looked up with no
 * lock, as in the lean binding (lean_binding.c). There is no log line for it: the host's logger is the instance's.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmi2_binding.h"

/* the FMI 2.0 loader's file name beside this library: given by the build (pmsm_ev_fmus.build.FMI3_INNER_LOADER) */
#ifndef FMI2_LOADER
#error "compile with -DFMI2_LOADER=\"<file name>\" (pmsm_ev_fmus.build does)"
#endif
/* the value reference of the independent variable `time` the FMI 3.0 model description declares (FMI 2.0 has
 * none): given by the build (pmsm_ev_fmus.build.FMI3_TIME_REFERENCE), beyond pythonfmu's value references */
#ifndef TIME_REFERENCE
#error "compile with -DTIME_REFERENCE=<value reference> (pmsm_ev_fmus.build does)"
#endif
/* a communication point continues the last step within this share of its size: the slaves' and the lean binding's
 * (pmsm_ev_fmus.slave_support.CONTINUITY_TOLERANCE, given by the build) */
#ifndef CONTINUITY_TOLERANCE
#error "compile with -DCONTINUITY_TOLERANCE=<share> (pmsm_ev_fmus.build does)"
#endif
/* in event mode a step may end past the next tick by this share of the sample period (the rounding of t + h: an ulp
 * of 350 s is 6e-10 of a 100 us period), no more: a step past a tick that was not set is refused */
#define TICK_SLACK 1e-6

/* -- the FMI 2.0 stack ------------------------------------------------------------------------------------ */
typedef struct {
    instantiate_t instantiate;
    free_t free_instance;
    debug_t debug_logging;
    setup_t setup;
    plain_t enter_init, exit_init, terminate, reset;
    get_real_t get_real;
    set_real_t set_real;
    get_int_t get_int, get_bool;
    set_int_t set_int, set_bool;
    get_str_t get_str;
    set_str_t set_str;
    state_t get_state, free_state;
    set_state_t set_state;
    state_size_t state_size;
    serialize_t serialize;
    deserialize_t deserialize;
    do_step_t do_step;
    real_status_t real_status;
    bool_status_t bool_status;
} Stack;

static Stack fmi2;
static void* loader = NULL;
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;

#include "own_directory.h" /* own_directory: the directory of this library */

/* load the FMI 2.0 loader beside this library and its functions, once: 0, or -1 with the reason in `why` */
static int load_stack(char* why, size_t size)
{
    int ok = 0;
    pthread_mutex_lock(&load_lock);
    if (loader == NULL) {
        char dir[PATH_MAX], path[PATH_MAX + 64];
        own_directory(dir, sizeof dir);
        snprintf(path, sizeof path, "%s%s", dir, FMI2_LOADER);
        void* library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
        if (library == NULL) {
            snprintf(why, size, "cannot load the FMI 2.0 stack %s: %s", path, dlerror());
            ok = -1;
        } else {
            Stack s;
            const char* missing = NULL;
#define LOAD(field, type, name)                                                                              \
    do {                                                                                                     \
        s.field = (type)dlsym(library, name);                                                                \
        if (s.field == NULL && missing == NULL) missing = name;                                              \
    } while (0)
            LOAD(instantiate, instantiate_t, "fmi2Instantiate");
            LOAD(free_instance, free_t, "fmi2FreeInstance");
            LOAD(debug_logging, debug_t, "fmi2SetDebugLogging");
            LOAD(setup, setup_t, "fmi2SetupExperiment");
            LOAD(enter_init, plain_t, "fmi2EnterInitializationMode");
            LOAD(exit_init, plain_t, "fmi2ExitInitializationMode");
            LOAD(terminate, plain_t, "fmi2Terminate");
            LOAD(reset, plain_t, "fmi2Reset");
            LOAD(get_real, get_real_t, "fmi2GetReal");
            LOAD(set_real, set_real_t, "fmi2SetReal");
            LOAD(get_int, get_int_t, "fmi2GetInteger");
            LOAD(get_bool, get_int_t, "fmi2GetBoolean");
            LOAD(set_int, set_int_t, "fmi2SetInteger");
            LOAD(set_bool, set_int_t, "fmi2SetBoolean");
            LOAD(get_str, get_str_t, "fmi2GetString");
            LOAD(set_str, set_str_t, "fmi2SetString");
            LOAD(get_state, state_t, "fmi2GetFMUstate");
            LOAD(free_state, state_t, "fmi2FreeFMUstate");
            LOAD(set_state, set_state_t, "fmi2SetFMUstate");
            LOAD(state_size, state_size_t, "fmi2SerializedFMUstateSize");
            LOAD(serialize, serialize_t, "fmi2SerializeFMUstate");
            LOAD(deserialize, deserialize_t, "fmi2DeSerializeFMUstate");
            LOAD(do_step, do_step_t, "fmi2DoStep");
            LOAD(real_status, real_status_t, "fmi2GetRealStatus");
            LOAD(bool_status, bool_status_t, "fmi2GetBooleanStatus");
#undef LOAD
            if (missing != NULL) {
                snprintf(why, size, "the FMI 2.0 stack %s has no %s", path, missing);
                dlclose(library);
                ok = -1;
            } else {
                fmi2 = s;
                loader = library;
            }
        }
    }
    pthread_mutex_unlock(&load_lock);
    return ok;
}

/* -- an instance ------------------------------------------------------------------------------------------ */
typedef struct {
    fmi2Component inner;              /* the FMI 2.0 stack's instance */
    /* the calls of every step: the binding's own functions, which the loader's only forward (pmsm_fmu_forwarded),
     * else the loader's: one hop less a call, the same answer (direct_calls) */
    get_real_t get_real;
    set_real_t set_real;
    do_step_t do_step;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log;       /* the host's (may be NULL) */
    fmi2CallbackFunctions callbacks;  /* given to fmi2Instantiate: relay, calloc, free; environment = this */
    double time;                      /* the independent variable: the start time, then where the last step ended */
    /* the sample clock of a controller (resources/CLOCK_FILE; clocked = 0: none) */
    int clocked;
    fmi3ValueReference clock_reference, dt_reference;
    fmi3ValueReference own_floor;     /* the least of the layer's own references (the time, the clock) */
    double interval;                  /* the clock's interval: the sample period */
    /* event mode (eventModeUsed): the stack steps only at the clock's ticks, one sample period each */
    int event_mode_used, in_event_mode, initialized, ticked;
    double stack_time;                /* where the stack's last step ended (event mode: the next tick) */
} Instance;

/* the sample clock of the unit: a line "<clock value reference> <interval [s]> <value reference of dt>" in this
 * file of resources/ (written by pmsm_ev_fmus.build for the controllers) */
#ifndef CLOCK_FILE
#error "compile with -DCLOCK_FILE=\"<file name>\" (pmsm_ev_fmus.build does)"
#endif

/* the instances this layer made: the instance table (instance_table.h), as the lean binding's */
#include "instance_table.h"

/* an FMI 2.0 status as FMI 3.0's: the same number for the five they share (fmi2Pending, never returned in this
 * co-simulation, is fmi3Error); one compare, on every call */
_Static_assert((int)fmi2OK == (int)fmi3OK && (int)fmi2Warning == (int)fmi3Warning
                   && (int)fmi2Discard == (int)fmi3Discard && (int)fmi2Error == (int)fmi3Error
                   && (int)fmi2Fatal == (int)fmi3Fatal,
               "the FMI 2.0 and FMI 3.0 statuses share their numbers");
static inline fmi3Status status3(fmi2Status s)
{
    return (unsigned)s <= (unsigned)fmi2Fatal ? (fmi3Status)s : fmi3Error;
}

static const char* category_of(fmi3Status s)
{
    switch (s) {
    case fmi3Warning: return "logStatusWarning";
    case fmi3Discard: return "logStatusDiscard";
    case fmi3Fatal: return "logStatusFatal";
    case fmi3OK: return "logAll";
    default: return "logStatusError";
    }
}

/* a message formatted (vsnprintf) into `stack`, or into a buffer allocated for it (to be freed if != stack) */
static char* format(char* stack, size_t size, const char* fmt, va_list ap)
{
    va_list again;
    va_copy(again, ap);
    int n = vsnprintf(stack, size, fmt, ap);
    char* text = stack;
    if (n >= 0 && (size_t)n >= size) {
        char* big = malloc((size_t)n + 1);
        if (big != NULL) {
            vsnprintf(big, (size_t)n + 1, fmt, again);
            text = big;
        }
    } else if (n < 0) {
        snprintf(stack, size, "%s", fmt);
    }
    va_end(again);
    return text;
}

/* the FMI 2.0 stack's logger: its message (a format, with arguments) formatted and handed to the host's fmi3
 * logMessage, with the status mapped; the 2.0 instance name is the 3.0 host's own */
static void relay(fmi2ComponentEnvironment environment, fmi2String name, fmi2Status status, fmi2String category,
                  fmi2String message, ...)
{
    (void)name;
    Instance* w = (Instance*)environment;
    if (w == NULL || w->log == NULL) return;
    char stack[1024];
    va_list ap;
    va_start(ap, message);
    char* text = format(stack, sizeof stack, message ? message : "", ap);
    va_end(ap);
    fmi3Status s = status3(status);
    w->log(w->environment, s, category ? category : category_of(s), text);
    if (text != stack) free(text);
}

/* one line of this layer's own to the host's logger */
static void say(fmi3InstanceEnvironment environment, fmi3LogMessageCallback log, fmi3Status status, const char* fmt,
                ...)
{
    if (log == NULL) return;
    char stack[1024];
    va_list ap;
    va_start(ap, fmt);
    char* text = format(stack, sizeof stack, fmt, ap);
    va_end(ap);
    log(environment, status, category_of(status), text);
    if (text != stack) free(text);
}

#define W ((Instance*)instance)
/* fmi3Error with one line, for a function that does not apply to this FMU (NULL or unknown instance: no line) */
#define NOT_HERE(why)                                                                                        \
    do {                                                                                                     \
        if (!live(instance)) return fmi3Error;                                                               \
        say(W->environment, W->log, fmi3Error, "%s: %s", __func__, why);                                     \
        return fmi3Error;                                                                                    \
    } while (0)
/* the scalar variables of this model: one value a value reference */
#define SCALARS(nvr, nvalues)                                                                                \
    do {                                                                                                     \
        if ((nvr) != (nvalues)) {                                                                            \
            say(W->environment, W->log, fmi3Error,                                                           \
                "%s: %zu values for %zu value references; the variables of this FMU are scalars", __func__,  \
                (size_t)(nvalues), (size_t)(nvr));                                                           \
            return fmi3Error;                                                                                \
        }                                                                                                    \
    } while (0)
/* none of the references the sample clock: a Clock is set by fmi3SetClock, and a host that takes it for a value is
 * answered here, not by the FMI 2.0 stack, which does not know the reference */
#define CLOCK_REFUSED_AS(call, refs, nvr)                                                                    \
    do {                                                                                                     \
        for (size_t clock_i = 0; W->clocked && clock_i < (nvr); clock_i++)                                   \
            if ((refs)[clock_i] == W->clock_reference) {                                                     \
                say(W->environment, W->log, fmi3Error, "%s: value reference %u is the sample clock, not a "     \
                    "value of this type (fmi3SetClock sets it); nothing done", (call),                       \
                    (unsigned)W->clock_reference);                                                           \
                return fmi3Error;                                                                            \
            }                                                                                                \
    } while (0)
#define CLOCK_REFUSED(refs, nvr) CLOCK_REFUSED_AS(__func__, refs, nvr)

/* whether any of the references is one of the layer's own (the time, the sample clock: the largest there are,
 * own_floor and above), one compare a reference: the get and set of Float64s, called at every step, pass the others
 * to the FMI 2.0 stack at once */
static inline int own_refs(const Instance* w, const fmi3ValueReference refs[], size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (refs[i] >= w->own_floor) return 1;
    return 0;
}

/* the resource folder (a path, ending in '/') as the file URI of FMI 2.0 (percent-encoded as fmpy's
 * pathname2url does); NULL: ../../resources/ from this library */
static char* resource_uri(fmi3String resourcePath)
{
    char folder[PATH_MAX];
    if (resourcePath != NULL && resourcePath[0]) {
        snprintf(folder, sizeof folder, "%s", resourcePath);
    } else {
        own_directory(folder, sizeof folder);
        size_t n = strlen(folder);
        snprintf(folder + n, sizeof folder - n, "../../resources/");
    }
    size_t n = strlen(folder);
    char* uri = malloc(3 * n + 16);
    if (uri == NULL) return NULL;
    size_t k = (size_t)sprintf(uri, "file://");
    static const char hex[] = "0123456789ABCDEF";
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)folder[i];
        if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || strchr("/_.-~", c)) {
            uri[k++] = (char)c;
        } else {
            uri[k++] = '%';
            uri[k++] = hex[c >> 4];
            uri[k++] = hex[c & 15];
        }
    }
    uri[k] = '\0';
    return uri;
}

/* the unit's sample clock from resources/CLOCK_FILE (uri: the resource folder's file URI, as made above) */
static void read_clock(Instance* w, const char* uri)
{
    char path[PATH_MAX + 64];
    const char* folder = strncmp(uri, "file://", 7) == 0 ? uri + 7 : uri;
    size_t k = 0;
    for (const char* c = folder; *c && k + 1 < PATH_MAX; c++) { /* percent-decoded */
        if (c[0] == '%' && c[1] && c[2]) {
            char hex[3] = {c[1], c[2], 0};
            path[k++] = (char)strtol(hex, NULL, 16);
            c += 2;
        } else {
            path[k++] = *c;
        }
    }
    path[k] = '\0';
    snprintf(path + k, sizeof path - k, "%s", CLOCK_FILE);
    FILE* f = fopen(path, "r");
    if (f == NULL) return;
    unsigned clock, dt;
    double interval;
    if (fscanf(f, "%u %lf %u", &clock, &interval, &dt) == 3 && interval > 0) {
        w->clocked = 1;
        w->clock_reference = clock;
        if (clock < w->own_floor) w->own_floor = clock;
        w->interval = interval;
        w->dt_reference = dt;
    }
    fclose(f);
}

/* the instance's calls of every step (fmi2GetReal, fmi2SetReal, fmi2DoStep): the binding's own without its look-up
 * of the instance (pmsm_fmu_known: this layer looks its own up at every call, and frees the FMI 2.0 instance only in
 * fmi3FreeInstance, once its own is out of its table), else the binding's own, which the loader's forward unchanged
 * (pmsm_fmu_forwarded), where the loader gives them (once the binding is loaded), else the loader's */
static void direct_calls(Instance* w)
{
    static const char* const NAMES[] = {"fmi2GetReal", "fmi2SetReal", "fmi2DoStep"};
    void* found[3] = {NULL, NULL, NULL};
    forwarded_t known = (forwarded_t)dlsym(loader, "pmsm_fmu_known");
    forwarded_t forwarded = (forwarded_t)dlsym(loader, "pmsm_fmu_forwarded");
    for (int i = 0; i < 3; i++) {
        if (known != NULL) found[i] = known(NAMES[i]);
        if (found[i] == NULL && forwarded != NULL) found[i] = forwarded(NAMES[i]);
    }
    w->get_real = found[0] ? (get_real_t)found[0] : fmi2.get_real;
    w->set_real = found[1] ? (set_real_t)found[1] : fmi2.set_real;
    w->do_step = found[2] ? (do_step_t)found[2] : fmi2.do_step;
}

/* -- common functions ------------------------------------------------------------------------------------ */
const char* fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    if (!live(instance)) return fmi3Error;
    return status3(fmi2.debug_logging(W->inner, loggingOn ? 1 : 0, nCategories, categories));
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    say(instanceEnvironment, logMessage, fmi3Error,
        "fmi3InstantiateModelExchange: this FMU is for co-simulation only (fmi3InstantiateCoSimulation)");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    say(instanceEnvironment, logMessage, fmi3Error,
        "fmi3InstantiateScheduledExecution: this FMU is for co-simulation only (fmi3InstantiateCoSimulation)");
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)earlyReturnAllowed, (void)requiredIntermediateVariables, (void)intermediateUpdate;
    char why[PATH_MAX + 256];
    if (nRequiredIntermediateVariables > 0) {
        say(instanceEnvironment, logMessage, fmi3Error,
            "fmi3InstantiateCoSimulation: %zu required intermediate variables, but this FMU provides no "
            "intermediate update", nRequiredIntermediateVariables);
        return NULL;
    }
    if (load_stack(why, sizeof why) != 0) {
        say(instanceEnvironment, logMessage, fmi3Error, "fmi3InstantiateCoSimulation: %s", why);
        return NULL;
    }
    Instance* w = calloc(1, sizeof(Instance));
    char* uri = resource_uri(resourcePath);
    if (w == NULL || uri == NULL) {
        free(w);
        free(uri);
        say(instanceEnvironment, logMessage, fmi3Error, "fmi3InstantiateCoSimulation: out of memory");
        return NULL;
    }
    w->environment = instanceEnvironment;
    w->log = logMessage;
    w->own_floor = TIME_REFERENCE;
    read_clock(w, uri);
    if (eventModeUsed && !w->clocked) {
        say(instanceEnvironment, logMessage, fmi3Error,
            "fmi3InstantiateCoSimulation: eventModeUsed, but this FMU has no event mode (hasEventMode=\"false\")");
        free(w);
        free(uri);
        return NULL;
    }
    w->event_mode_used = eventModeUsed ? 1 : 0;
    w->callbacks.logger = relay;
    w->callbacks.allocateMemory = calloc;
    w->callbacks.freeMemory = free;
    w->callbacks.stepFinished = NULL;
    w->callbacks.componentEnvironment = w;
    w->inner = fmi2.instantiate(instanceName ? instanceName : "", fmi2CoSimulation,
                                instantiationToken ? instantiationToken : "", uri, &w->callbacks, visible ? 1 : 0,
                                loggingOn ? 1 : 0);
    free(uri);
    if (w->inner == NULL) { /* the stack logged why */
        free(w);
        return NULL;
    }
    direct_calls(w);
    if (!enlist(w)) {
        say(instanceEnvironment, logMessage, fmi3Error, "fmi3InstantiateCoSimulation: more than %d instances at once",
            LIVE_INSTANCES);
        fmi2.free_instance(w->inner);
        free(w);
        return NULL;
    }
    return w;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    if (!delist(instance)) return; /* NULL, not this layer's, or freed already: nothing */
    fmi2.free_instance(W->inner);
    free(W);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    if (!live(instance)) return fmi3Error;
    fmi2Status setup = fmi2.setup(W->inner, toleranceDefined ? 1 : 0, tolerance, startTime, stopTimeDefined ? 1 : 0,
                                  stopTime);
    if (setup > fmi2Warning) return status3(setup);
    fmi2Status enter = fmi2.enter_init(W->inner);
    if (enter <= fmi2Warning) W->time = startTime;
    return status3(enter > setup ? enter : setup);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    if (!live(instance)) return fmi3Error;
    if (W->event_mode_used) { /* the stack samples once a tick: its sample period must be the clock's */
        fmi2ValueReference ref = W->dt_reference;
        fmi2Real dt = 0.0;
        if (W->get_real(W->inner, &ref, 1, &dt) <= fmi2Warning && dt != 0.0 && dt != W->interval) {
            say(W->environment, W->log, fmi3Error,
                "fmi3ExitInitializationMode: dt = %.9g s, but the sample clock ticks every %.9g s in event mode "
                "(set dt to 0 or to the clock's interval)", dt, W->interval);
            return fmi3Error;
        }
    }
    fmi2Status s = fmi2.exit_init(W->inner);
    if (s <= fmi2Warning) {
        W->initialized = 1;
        W->stack_time = W->time;
    }
    return status3(s);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    if (!live(instance)) return fmi3Error;
    if (!W->clocked) NOT_HERE("this FMU has no event mode");
    if (!W->event_mode_used) NOT_HERE("event mode was not asked for at instantiation (eventModeUsed false): the "
                                      "unit samples at its own period in fmi3DoStep");
    if (!W->initialized) NOT_HERE("before fmi3ExitInitializationMode");
    W->in_event_mode = 1;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    if (!live(instance)) return fmi3Error;
    fmi2Status s = fmi2.terminate(W->inner);
    if (s <= fmi2Warning) W->initialized = W->in_event_mode = W->ticked = 0; /* a step now: the stack's refusal */
    return status3(s);
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    if (!live(instance)) return fmi3Error;
    fmi2Status s = fmi2.reset(W->inner);
    if (s <= fmi2Warning) W->initialized = W->in_event_mode = W->ticked = 0;
    return status3(s);
}

/* -- getting and setting values -------------------------------------------------------------------------- */
/* fmi3GetFloat64 with one of the layer's own references among them (the clock: refused; the time: answered here),
 * out of line: the get of every step keeps no more than it needs */
static __attribute__((noinline)) fmi3Status get_own_float64(fmi3Instance instance,
                                                           const fmi3ValueReference valueReferences[],
                                                           size_t nValueReferences, fmi3Float64 values[])
{
    CLOCK_REFUSED_AS("fmi3GetFloat64", valueReferences, nValueReferences);
    size_t times = 0;
    for (size_t i = 0; i < nValueReferences; i++) times += valueReferences[i] == TIME_REFERENCE;
    if (times == 0) return status3(W->get_real(W->inner, valueReferences, nValueReferences, values));
    /* the time among them: the others from the stack */
    size_t n = nValueReferences - times, k = 0;
    fmi2ValueReference* refs = malloc((n ? n : 1) * sizeof(fmi2ValueReference));
    fmi2Real* got = malloc((n ? n : 1) * sizeof(fmi2Real));
    fmi2Status s = fmi2Error;
    if (refs != NULL && got != NULL) {
        for (size_t i = 0; i < nValueReferences; i++)
            if (valueReferences[i] != TIME_REFERENCE) refs[k++] = valueReferences[i];
        s = n ? W->get_real(W->inner, refs, n, got) : fmi2OK;
        if (s <= fmi2Warning)
            for (size_t i = 0, j = 0; i < nValueReferences; i++)
                values[i] = valueReferences[i] == TIME_REFERENCE ? W->time : got[j++];
    }
    free(refs);
    free(got);
    return status3(s);
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    if (!own_refs(W, valueReferences, nValueReferences))
        return status3(W->get_real(W->inner, valueReferences, nValueReferences, values));
    return get_own_float64(instance, valueReferences, nValueReferences, values);
}

/* fmi3SetFloat64 with one of the layer's own references among them (the clock, the time: refused), out of line */
static __attribute__((noinline)) fmi3Status set_own_float64(fmi3Instance instance,
                                                           const fmi3ValueReference valueReferences[],
                                                           size_t nValueReferences, const fmi3Float64 values[])
{
    CLOCK_REFUSED_AS("fmi3SetFloat64", valueReferences, nValueReferences);
    for (size_t i = 0; i < nValueReferences; i++)
        if (valueReferences[i] == TIME_REFERENCE) {
            say(W->environment, W->log, fmi3Error, "fmi3SetFloat64: the independent variable time cannot be set; "
                "nothing set");
            return fmi3Error;
        }
    return status3(W->set_real(W->inner, valueReferences, nValueReferences, values));
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    if (!own_refs(W, valueReferences, nValueReferences))
        return status3(W->set_real(W->inner, valueReferences, nValueReferences, values));
    return set_own_float64(instance, valueReferences, nValueReferences, values);
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    CLOCK_REFUSED(valueReferences, nValueReferences);
    return status3(fmi2.get_int(W->inner, valueReferences, nValueReferences, (fmi2Integer*)values));
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    CLOCK_REFUSED(valueReferences, nValueReferences);
    return status3(fmi2.set_int(W->inner, valueReferences, nValueReferences, (const fmi2Integer*)values));
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Boolean values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    CLOCK_REFUSED(valueReferences, nValueReferences);
    fmi2Boolean* wide = calloc(nValueReferences ? nValueReferences : 1, sizeof(fmi2Boolean));
    if (wide == NULL) return fmi3Error;
    fmi2Status s = fmi2.get_bool(W->inner, valueReferences, nValueReferences, wide);
    if (s <= fmi2Warning)
        for (size_t i = 0; i < nValueReferences; i++) values[i] = wide[i] != 0;
    free(wide);
    return status3(s);
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Boolean values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    CLOCK_REFUSED(valueReferences, nValueReferences);
    fmi2Boolean* wide = calloc(nValueReferences ? nValueReferences : 1, sizeof(fmi2Boolean));
    if (wide == NULL) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) wide[i] = values[i] ? 1 : 0;
    fmi2Status s = fmi2.set_bool(W->inner, valueReferences, nValueReferences, wide);
    free(wide);
    return status3(s);
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         fmi3String values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    CLOCK_REFUSED(valueReferences, nValueReferences);
    return status3(fmi2.get_str(W->inner, valueReferences, nValueReferences, values));
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const fmi3String values[], size_t nValues)
{
    if (!live(instance)) return fmi3Error;
    SCALARS(nValueReferences, nValues);
    CLOCK_REFUSED(valueReferences, nValueReferences);
    return status3(fmi2.set_str(W->inner, valueReferences, nValueReferences, values));
}

/* the types this model has none of */
#define NO_TYPE(name, type, constness)                                                                       \
    fmi3Status name(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                    constness type values[], size_t nValues)                                                 \
    {                                                                                                        \
        (void)valueReferences, (void)nValueReferences, (void)values, (void)nValues;                          \
        NOT_HERE("this FMU has no variable of type " #type);                                                 \
    }
NO_TYPE(fmi3GetFloat32, fmi3Float32, )
NO_TYPE(fmi3GetInt8, fmi3Int8, )
NO_TYPE(fmi3GetUInt8, fmi3UInt8, )
NO_TYPE(fmi3GetInt16, fmi3Int16, )
NO_TYPE(fmi3GetUInt16, fmi3UInt16, )
NO_TYPE(fmi3GetUInt32, fmi3UInt32, )
NO_TYPE(fmi3GetInt64, fmi3Int64, )
NO_TYPE(fmi3GetUInt64, fmi3UInt64, )
NO_TYPE(fmi3SetFloat32, fmi3Float32, const)
NO_TYPE(fmi3SetInt8, fmi3Int8, const)
NO_TYPE(fmi3SetUInt8, fmi3UInt8, const)
NO_TYPE(fmi3SetInt16, fmi3Int16, const)
NO_TYPE(fmi3SetUInt16, fmi3UInt16, const)
NO_TYPE(fmi3SetUInt32, fmi3UInt32, const)
NO_TYPE(fmi3SetInt64, fmi3Int64, const)
NO_TYPE(fmi3SetUInt64, fmi3UInt64, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueReferences, (void)nValueReferences, (void)valueSizes, (void)values, (void)nValues;
    NOT_HERE("this FMU has no variable of type fmi3Binary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)valueReferences, (void)nValueReferences, (void)valueSizes, (void)values, (void)nValues;
    NOT_HERE("this FMU has no variable of type fmi3Binary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[])
{
    (void)valueReferences, (void)nValueReferences, (void)values;
    if (live(instance) && W->clocked) NOT_HERE("the sample clock is an input clock: the host sets it (fmi3SetClock)");
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[])
{
    if (!live(instance)) return fmi3Error;
    if (!W->clocked) NOT_HERE("this FMU has no clock");
    if (!W->in_event_mode) NOT_HERE("outside event mode: a clock ticks in event mode (fmi3EnterEventMode first); "
                                    "nothing set");
    for (size_t i = 0; i < nValueReferences; i++)
        if (valueReferences[i] != W->clock_reference) {
            say(W->environment, W->log, fmi3Error, "fmi3SetClock: value reference %u is not a clock of this FMU "
                "(the sample clock is %u); nothing set", (unsigned)valueReferences[i], (unsigned)W->clock_reference);
            return fmi3Error;
        }
    for (size_t i = 0; i < nValueReferences; i++)
        if (values[i]) W->ticked = 1;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t* nDependencies)
{
    (void)valueReference, (void)nDependencies;
    NOT_HERE("not provided: the dependencies are in modelDescription.xml (ModelStructure)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    NOT_HERE("not provided: the dependencies are in modelDescription.xml (ModelStructure)");
}

/* -- the FMU state --------------------------------------------------------------------------------------- */
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState* FMUState)
{
    if (!live(instance)) return fmi3Error;
    return status3(fmi2.get_state(W->inner, (fmi2FMUstate*)FMUState));
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    if (!live(instance)) return fmi3Error;
    fmi2Status s = fmi2.set_state(W->inner, (fmi2FMUstate)FMUState);
    fmi2Real reached;
    if (s <= fmi2Warning && fmi2.real_status(W->inner, fmi2LastSuccessfulTime, &reached) <= fmi2Warning &&
        reached == reached)
        W->time = W->stack_time = reached;
    if (s <= fmi2Warning) W->ticked = W->in_event_mode = 0;
    return status3(s);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState* FMUState)
{
    if (!live(instance)) return fmi3Error;
    return status3(fmi2.free_state(W->inner, (fmi2FMUstate*)FMUState));
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t* size)
{
    if (!live(instance)) return fmi3Error;
    return status3(fmi2.state_size(W->inner, (fmi2FMUstate)FMUState, size));
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    if (!live(instance)) return fmi3Error;
    return status3(fmi2.serialize(W->inner, (fmi2FMUstate)FMUState, (fmi2Byte*)serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState* FMUState)
{
    if (!live(instance)) return fmi3Error;
    return status3(fmi2.deserialize(W->inner, (const fmi2Byte*)serializedState, size, (fmi2FMUstate*)FMUState));
}

/* -- derivatives, configuration, clocks, discrete states: none here --------------------------------------- */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    NOT_HERE("this FMU provides no directional derivatives");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    NOT_HERE("this FMU provides no adjoint derivatives");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { NOT_HERE("this FMU has no structural parameter"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { NOT_HERE("this FMU has no structural parameter"); }

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    if (!live(instance)) return fmi3Error;
    if (!W->clocked) NOT_HERE("this FMU has no clock");
    for (size_t i = 0; i < nValueReferences; i++) {
        if (valueReferences[i] != W->clock_reference) NOT_HERE("not a clock of this FMU");
        intervals[i] = W->interval;
        qualifiers[i] = fmi3IntervalUnchanged; /* intervalVariability="constant" */
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions, (void)qualifiers;
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences, (void)nValueReferences, (void)intervals;
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    NOT_HERE("this FMU has no clock");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { NOT_HERE("this FMU has no event mode"); }

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean* discreteStatesNeedUpdate,
                                    fmi3Boolean* terminateSimulation, fmi3Boolean* nominalsOfContinuousStatesChanged,
                                    fmi3Boolean* valuesOfContinuousStatesChanged, fmi3Boolean* nextEventTimeDefined,
                                    fmi3Float64* nextEventTime)
{
    if (!live(instance)) return fmi3Error;
    if (!W->clocked) NOT_HERE("this FMU has no event mode");
    if (!W->in_event_mode) NOT_HERE("outside event mode (fmi3EnterEventMode first)");
    fmi2Status s = fmi2OK;
    if (W->ticked) { /* the tick: one sample period of the stack from now, its sample at this instant */
        s = W->do_step(W->inner, W->time, W->interval, 1);
        if (s <= fmi2Warning) {
            W->stack_time = W->time + W->interval;
            W->ticked = 0;
        }
    }
    if (discreteStatesNeedUpdate != NULL) *discreteStatesNeedUpdate = false;
    if (terminateSimulation != NULL) *terminateSimulation = s == fmi2Fatal;
    if (nominalsOfContinuousStatesChanged != NULL) *nominalsOfContinuousStatesChanged = false;
    if (valuesOfContinuousStatesChanged != NULL) *valuesOfContinuousStatesChanged = false;
    if (nextEventTimeDefined != NULL) *nextEventTimeDefined = true;
    if (nextEventTime != NULL) *nextEventTime = W->stack_time;
    return status3(s);
}

/* -- model exchange: not this FMU ------------------------------------------------------------------------ */
#define ME_ONLY "a function of model exchange; this FMU is for co-simulation"
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) { NOT_HERE(ME_ONLY); }

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean* enterEventMode, fmi3Boolean* terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    (void)time;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates, (void)nContinuousStates;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    (void)derivatives, (void)nContinuousStates;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    (void)eventIndicators, (void)nEventIndicators;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    (void)continuousStates, (void)nContinuousStates;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates)
{
    (void)nominals, (void)nContinuousStates;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t* nEventIndicators)
{
    (void)nEventIndicators;
    NOT_HERE(ME_ONLY);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t* nContinuousStates)
{
    (void)nContinuousStates;
    NOT_HERE(ME_ONLY);
}

/* -- co-simulation --------------------------------------------------------------------------------------- */
fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    if (!live(instance)) return fmi3Error;
    if (!W->clocked) NOT_HERE("this FMU has no event mode (it is in step mode)");
    if (!W->in_event_mode) NOT_HERE("not in event mode");
    if (W->ticked) NOT_HERE("the clock ticked, but fmi3UpdateDiscreteStates has not run its sample");
    W->in_event_mode = 0;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)valueReferences, (void)nValueReferences, (void)orders, (void)values, (void)nValues;
    NOT_HERE("this FMU provides no output derivatives (maxOutputDerivativeOrder 0)");
}

/* fmi3DoStep in event mode: the stack stepped at the tick (fmi3UpdateDiscreteStates), up to the next tick; a step
 * here only moves the time, within that sample period, with the outputs held (the controller's change only at its
 * samples) */
static __attribute__((noinline)) fmi3Status clocked_step(Instance* w, double t, double h, fmi3Boolean* eventHandlingNeeded,
                               fmi3Boolean* terminateSimulation, fmi3Boolean* earlyReturn,
                               fmi3Float64* lastSuccessfulTime)
{
    double end = t + h, slack = TICK_SLACK * w->interval;
    fmi3Status s = fmi3OK;
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = false;
    if (terminateSimulation != NULL) *terminateSimulation = false;
    if (earlyReturn != NULL) *earlyReturn = false;
    if (lastSuccessfulTime != NULL) *lastSuccessfulTime = t;
    if (w->in_event_mode) {
        say(w->environment, w->log, fmi3Error, "fmi3DoStep in event mode (fmi3EnterStepMode first)");
        s = fmi3Error;
    } else if (!(h > 0.0)) {
        say(w->environment, w->log, fmi3Error, "fmi3DoStep of %.9g s: a step size > 0", h);
        s = fmi3Error;
    } else if (fabs(t - w->time) > CONTINUITY_TOLERANCE * h) {
        say(w->environment, w->log, fmi3Error, "fmi3DoStep at t = %.9g s does not continue the last step, which "
            "ended at %.9g s", t, w->time);
        s = fmi3Error;
    } else if (end > w->stack_time + slack) {
        say(w->environment, w->log, fmi3Error, "fmi3DoStep to t = %.9g s passes the sample clock's tick at %.9g s, "
            "which was not set (in event mode, set the clock at each tick: fmi3EnterEventMode, fmi3SetClock, "
            "fmi3UpdateDiscreteStates)", end, w->stack_time);
        s = fmi3Error;
    } else {
        w->time = end;
        if (lastSuccessfulTime != NULL) *lastSuccessfulTime = end;
    }
    return s;
}

static fmi3Status step_not_done(Instance* w, fmi2Status s, double currentCommunicationPoint,
                                fmi3Boolean* eventHandlingNeeded, fmi3Boolean* terminateSimulation,
                                fmi3Boolean* earlyReturn, fmi3Float64* lastSuccessfulTime);

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean* eventHandlingNeeded, fmi3Boolean* terminateSimulation, fmi3Boolean* earlyReturn,
                      fmi3Float64* lastSuccessfulTime)
{
    if (!live(instance)) return fmi3Error;
    if (W->event_mode_used && W->initialized) return clocked_step(W, currentCommunicationPoint, communicationStepSize,
                                                                   eventHandlingNeeded, terminateSimulation,
                                                                   earlyReturn, lastSuccessfulTime);
    fmi2Status s = W->do_step(W->inner, currentCommunicationPoint, communicationStepSize,
                              noSetFMUStatePriorToCurrentPoint ? 1 : 0);
    if (s > fmi2Warning)
        return step_not_done(W, s, currentCommunicationPoint, eventHandlingNeeded, terminateSimulation, earlyReturn,
                             lastSuccessfulTime);
    W->time = currentCommunicationPoint + communicationStepSize;
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = false;
    if (terminateSimulation != NULL) *terminateSimulation = false;
    if (earlyReturn != NULL) *earlyReturn = false;
    if (lastSuccessfulTime != NULL) *lastSuccessfulTime = W->time;
    return (fmi3Status)s; /* fmi3OK, fmi3Warning */
}

/* fmi3DoStep's answer to a step the FMI 2.0 stack did not complete (fmi2Discard: where it got to and whether it ended
 * the run; fmi2Error, fmi2Fatal), out of line: the step of every step keeps no more than it needs */
static __attribute__((noinline)) fmi3Status step_not_done(Instance* w, fmi2Status s, double currentCommunicationPoint,
                                                         fmi3Boolean* eventHandlingNeeded,
                                                         fmi3Boolean* terminateSimulation, fmi3Boolean* earlyReturn,
                                                         fmi3Float64* lastSuccessfulTime)
{
    fmi3Instance instance = w;
    fmi3Boolean terminate = s == fmi2Fatal;
    fmi3Float64 last = currentCommunicationPoint; /* s > fmi2Warning here */
    if (s == fmi2Discard) { /* where the stack says it got to, and whether it ended the run */
        fmi2Real reached;
        fmi2Boolean ended;
        if (fmi2.real_status(W->inner, fmi2LastSuccessfulTime, &reached) <= fmi2Warning) last = reached;
        if (fmi2.bool_status(W->inner, fmi2Terminated, &ended) <= fmi2Warning) terminate = ended != 0;
    }
    if (s <= fmi2Discard) W->time = last;
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = false;
    if (terminateSimulation != NULL) *terminateSimulation = terminate;
    if (earlyReturn != NULL) *earlyReturn = false;
    if (lastSuccessfulTime != NULL) *lastSuccessfulTime = last;
    return status3(s);
}

/* -- the project's counters (fmus/README.md, "The lean binding", "The compiled step") ---------------------- */
/* pmsm_fmu_fast_calls, pmsm_fmu_compiled_calls, pmsm_fmu_pulls of an instance: the FMI 2.0 stack's counters of its
 * instance (0 for NULL or an unknown instance, or without the lean binding) */
static unsigned long long counter(const char* name, fmi3Instance instance)
{
    if (!live(instance) || loader == NULL) return 0;
    calls_t f = (calls_t)dlsym(loader, name);
    return f ? f(W->inner) : 0;
}

EXPORT unsigned long long pmsm_fmu_fast_calls(fmi3Instance instance)
{
    return counter("pmsm_fmu_fast_calls", instance);
}

EXPORT unsigned long long pmsm_fmu_compiled_calls(fmi3Instance instance)
{
    return counter("pmsm_fmu_compiled_calls", instance);
}

EXPORT unsigned long long pmsm_fmu_pulls(fmi3Instance instance)
{
    return counter("pmsm_fmu_pulls", instance);
}

/* -- scheduled execution: not this FMU ------------------------------------------------------------------- */
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference, (void)activationTime;
    NOT_HERE("a function of scheduled execution; this FMU is for co-simulation");
}
