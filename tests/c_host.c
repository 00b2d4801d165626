/* A minimal FMI 2.0 co-simulation host in C, for tests/test_c_host.py: no libpython linked, nothing of Python
 * in its process but what an FMU brings itself.
 *
 *   c_host SPEC
 *
 * SPEC is a text file of blocks, one per FMU, each run to its end before the next:
 *
 *   fmu <name> <binary .so> <resources URI> <guid>
 *   steps <n> <h>
 *   input <vr> <a> <b>     (a Real input: a + b k before step k)
 *   output <vr>            (a Real output printed after each step)
 *   run
 *
 * For each FMU it prints "fmu <name>", then one line per step: "<k> <status> <output values %.17g>...", then
 * "calls <fast> <compiled>": the lean binding's pmsm_fmu_fast_calls and pmsm_fmu_compiled_calls of the instance
 * (0 0 where the FMU's library has none).
 *
 * Or a system of FMUs, all loaded and instantiated at once and stepped by a Jacobi master (as OMSimulator's):
 *
 *   member <name> <binary .so> <resources URI> <guid>     (members numbered from 0)
 *   start <member> <vr> <R|I|B> <value>                    (set in initialization mode)
 *   connect <from member> <vr> <to member> <vr>            (Real)
 *   record <member> <vr>                                   (a Real printed after each step)
 *   steps <n> <h>
 *   run_system
 *
 * At each step k every member's connected outputs are read, then every input set, then every member stepped
 * from t = k h; then "<k> <worst status> <recorded values %.17g>..." is printed (the values at t_{k+1}).
 *
 * A line "keep" (anywhere before the runs) leaves every FMU's library loaded to the end of the process, as hosts do
 * that never unload one; by default each is unloaded (dlclose) after its run, as FMI Library's hosts (fmuCheck) do.
 *
 * What the FMU logs goes to stdout as "log <status> <category> <message>". Exit code 0 when every FMU ran
 * (whatever its statuses), 2 when a binary cannot be loaded, 3 when fmi2Instantiate returns NULL. */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    (void)instance;
    char text[8192];
    va_list ap;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    printf("log %d %s %s\n", (int)status, category ? category : "", text);
    fflush(stdout);
}

#define MAX_VARS 64

static int unload = 1; /* dlclose each FMU's library after its run ("keep": never) */

typedef struct {
    char name[256], binary[4096], resources[4096], guid[256];
    int steps;
    double h;
    int n_in, n_out;
    fmi2ValueReference in[MAX_VARS], out[MAX_VARS];
    double a[MAX_VARS], b[MAX_VARS];
} Spec;

#define LOAD(type, name)                                                                                   \
    type* name = (type*)dlsym(h, "fmi2" #name);                                                          \
    if (name == NULL) {                                                                                    \
        printf("no fmi2" #name " in %s\n", s->binary);                                                    \
        return 2;                                                                                          \
    }

static int run(const Spec* s)
{
    void* h = dlopen(s->binary, RTLD_NOW | RTLD_LOCAL);
    if (h == NULL) {
        printf("dlopen failed: %s\n", dlerror());
        return 2;
    }
    LOAD(fmi2GetVersionTYPE, GetVersion)
    LOAD(fmi2GetTypesPlatformTYPE, GetTypesPlatform)
    LOAD(fmi2InstantiateTYPE, Instantiate)
    LOAD(fmi2SetupExperimentTYPE, SetupExperiment)
    LOAD(fmi2EnterInitializationModeTYPE, EnterInitializationMode)
    LOAD(fmi2ExitInitializationModeTYPE, ExitInitializationMode)
    LOAD(fmi2SetRealTYPE, SetReal)
    LOAD(fmi2GetRealTYPE, GetReal)
    LOAD(fmi2DoStepTYPE, DoStep)
    LOAD(fmi2TerminateTYPE, Terminate)
    LOAD(fmi2FreeInstanceTYPE, FreeInstance)
    printf("fmu %s %s %s\n", s->name, GetVersion(), GetTypesPlatform());
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = Instantiate(s->name, fmi2CoSimulation, s->guid, s->resources, &cb, fmi2False, fmi2True);
    if (c == NULL) {
        printf("instantiate failed\n");
        return 3;
    }
    fmi2Status st = SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    if (st == fmi2OK) st = EnterInitializationMode(c);
    if (st == fmi2OK) st = ExitInitializationMode(c);
    printf("initialised %d\n", (int)st);
    double u[MAX_VARS], y[MAX_VARS];
    for (int k = 0; k < s->steps && st == fmi2OK; k++) {
        for (int i = 0; i < s->n_in; i++) u[i] = s->a[i] + s->b[i] * k;
        if (s->n_in) st = SetReal(c, s->in, (size_t)s->n_in, u);
        if (st == fmi2OK) st = DoStep(c, k * s->h, s->h, fmi2True);
        fmi2Status got = GetReal(c, s->out, (size_t)s->n_out, y);
        printf("%d %d %d", k, (int)st, (int)got);
        for (int i = 0; i < s->n_out; i++) printf(" %.17g", y[i]);
        printf("\n");
    }
    /* the lean binding's counters (fmus/README.md, "The compiled step"), through the loader; absent: none */
    typedef unsigned long long calls_t(fmi2Component);
    calls_t* fast = (calls_t*)dlsym(h, "pmsm_fmu_fast_calls");
    calls_t* compiled = (calls_t*)dlsym(h, "pmsm_fmu_compiled_calls");
    printf("calls %llu %llu\n", fast ? fast(c) : 0ULL, compiled ? compiled(c) : 0ULL);
    printf("terminate %d\n", (int)Terminate(c));
    FreeInstance(c);
    fflush(stdout);
    if (unload) dlclose(h); /* as FMI Library's hosts (fmuCheck) unload an FMU */
    return 0;
}

/* -- a system of FMUs, Jacobi ---------------------------------------------------------------------------- */
#define MAX_MEMBERS 8
#define MAX_LINKS 64

typedef struct {
    char name[256], binary[4096], resources[4096], guid[256];
    void* h;
    fmi2Component c;
    fmi2SetRealTYPE* set_real;
    fmi2GetRealTYPE* get_real;
    fmi2DoStepTYPE* do_step;
} Member;

typedef struct {
    int n_members, n_starts, n_links, n_records, steps;
    double h;
    Member m[MAX_MEMBERS];
    struct { int member; fmi2ValueReference vr; char type; double value; } start[MAX_LINKS];
    struct { int from, to; fmi2ValueReference from_vr, to_vr; double value; } link[MAX_LINKS];
    struct { int member; fmi2ValueReference vr; } record[MAX_LINKS];
} System;

static int run_system(System* s)
{
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    for (int i = 0; i < s->n_members; i++) {
        Member* m = &s->m[i];
        m->h = dlopen(m->binary, RTLD_NOW | RTLD_LOCAL);
        if (m->h == NULL) {
            printf("dlopen failed: %s\n", dlerror());
            return 2;
        }
        fmi2InstantiateTYPE* instantiate = (fmi2InstantiateTYPE*)dlsym(m->h, "fmi2Instantiate");
        m->set_real = (fmi2SetRealTYPE*)dlsym(m->h, "fmi2SetReal");
        m->get_real = (fmi2GetRealTYPE*)dlsym(m->h, "fmi2GetReal");
        m->do_step = (fmi2DoStepTYPE*)dlsym(m->h, "fmi2DoStep");
        m->c = instantiate(m->name, fmi2CoSimulation, m->guid, m->resources, &cb, fmi2False, fmi2True);
        if (m->c == NULL) {
            printf("instantiate failed\n");
            return 3;
        }
    }
    int st = 0;
    for (int i = 0; i < s->n_members; i++) {
        Member* m = &s->m[i];
        fmi2SetupExperimentTYPE* setup = (fmi2SetupExperimentTYPE*)dlsym(m->h, "fmi2SetupExperiment");
        fmi2EnterInitializationModeTYPE* enter =
            (fmi2EnterInitializationModeTYPE*)dlsym(m->h, "fmi2EnterInitializationMode");
        fmi2SetIntegerTYPE* set_int = (fmi2SetIntegerTYPE*)dlsym(m->h, "fmi2SetInteger");
        fmi2SetBooleanTYPE* set_bool = (fmi2SetBooleanTYPE*)dlsym(m->h, "fmi2SetBoolean");
        st |= setup(m->c, fmi2False, 0.0, 0.0, fmi2False, 0.0) | enter(m->c);
        for (int j = 0; j < s->n_starts; j++) {
            if (s->start[j].member != i) continue;
            fmi2Real r = s->start[j].value;
            fmi2Integer k = (fmi2Integer)s->start[j].value;
            if (s->start[j].type == 'R') st |= m->set_real(m->c, &s->start[j].vr, 1, &r);
            else if (s->start[j].type == 'I') st |= set_int(m->c, &s->start[j].vr, 1, &k);
            else st |= set_bool(m->c, &s->start[j].vr, 1, &k);
        }
    }
    for (int i = 0; i < s->n_members; i++) {
        fmi2ExitInitializationModeTYPE* leave =
            (fmi2ExitInitializationModeTYPE*)dlsym(s->m[i].h, "fmi2ExitInitializationMode");
        st |= leave(s->m[i].c);
    }
    printf("system initialised %d\n", st);
    for (int k = 0; k < s->steps && st == 0; k++) {
        int worst = 0;
        for (int j = 0; j < s->n_links; j++) {
            Member* m = &s->m[s->link[j].from];
            worst |= m->get_real(m->c, &s->link[j].from_vr, 1, &s->link[j].value);
        }
        for (int j = 0; j < s->n_links; j++) {
            Member* m = &s->m[s->link[j].to];
            worst |= m->set_real(m->c, &s->link[j].to_vr, 1, &s->link[j].value);
        }
        for (int i = 0; i < s->n_members; i++) {
            int status = s->m[i].do_step(s->m[i].c, k * s->h, s->h, fmi2True);
            if (status > worst) worst = status;
        }
        printf("%d %d", k, worst);
        for (int j = 0; j < s->n_records; j++) {
            Member* m = &s->m[s->record[j].member];
            double y = 0.0;
            worst |= m->get_real(m->c, &s->record[j].vr, 1, &y);
            printf(" %.17g", y);
        }
        printf("\n");
        st = worst;
    }
    for (int i = 0; i < s->n_members; i++) {
        Member* m = &s->m[i];
        ((fmi2TerminateTYPE*)dlsym(m->h, "fmi2Terminate"))(m->c);
        ((fmi2FreeInstanceTYPE*)dlsym(m->h, "fmi2FreeInstance"))(m->c);
    }
    for (int i = 0; i < s->n_members && unload; i++) dlclose(s->m[i].h);
    fflush(stdout);
    return 0;
}

int main(int argc, char** argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: c_host SPEC\n");
        return 1;
    }
    FILE* f = fopen(argv[1], "r");
    if (f == NULL) {
        perror(argv[1]);
        return 1;
    }
    static Spec s;
    static System sys;
    char line[16384];
    while (fgets(line, sizeof line, f) != NULL) {
        line[strcspn(line, "\n")] = '\0';
        if (strncmp(line, "member ", 7) == 0 && sys.n_members < MAX_MEMBERS) {
            Member* m = &sys.m[sys.n_members++];
            sscanf(line + 7, "%255s %4095s %4095s %255s", m->name, m->binary, m->resources, m->guid);
        } else if (strncmp(line, "start ", 6) == 0 && sys.n_starts < MAX_LINKS) {
            sscanf(line + 6, "%d %u %c %lf", &sys.start[sys.n_starts].member, &sys.start[sys.n_starts].vr,
                   &sys.start[sys.n_starts].type, &sys.start[sys.n_starts].value);
            sys.n_starts++;
        } else if (strncmp(line, "connect ", 8) == 0 && sys.n_links < MAX_LINKS) {
            sscanf(line + 8, "%d %u %d %u", &sys.link[sys.n_links].from, &sys.link[sys.n_links].from_vr,
                   &sys.link[sys.n_links].to, &sys.link[sys.n_links].to_vr);
            sys.n_links++;
        } else if (strncmp(line, "record ", 7) == 0 && sys.n_records < MAX_LINKS) {
            sscanf(line + 7, "%d %u", &sys.record[sys.n_records].member, &sys.record[sys.n_records].vr);
            sys.n_records++;
        } else if (strcmp(line, "run_system") == 0) {
            sys.steps = s.steps;
            sys.h = s.h;
            int rc = run_system(&sys);
            if (rc != 0) return rc;
        } else if (strncmp(line, "fmu ", 4) == 0) {
            memset(&s, 0, sizeof s);
            sscanf(line + 4, "%255s %4095s %4095s %255s", s.name, s.binary, s.resources, s.guid);
        } else if (strncmp(line, "steps ", 6) == 0) {
            sscanf(line + 6, "%d %lf", &s.steps, &s.h);
        } else if (strncmp(line, "input ", 6) == 0 && s.n_in < MAX_VARS) {
            sscanf(line + 6, "%u %lf %lf", &s.in[s.n_in], &s.a[s.n_in], &s.b[s.n_in]);
            s.n_in++;
        } else if (strncmp(line, "output ", 7) == 0 && s.n_out < MAX_VARS) {
            sscanf(line + 7, "%u", &s.out[s.n_out++]);
        } else if (strcmp(line, "keep") == 0) {
            unload = 0;
        } else if (strcmp(line, "run") == 0) {
            int rc = run(&s);
            if (rc != 0) return rc;
        }
    }
    fclose(f);
    return 0;
}
