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
 * For each FMU it prints "fmu <name>", then one line per step: "<k> <status> <output values %.17g>...".
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
    printf("terminate %d\n", (int)Terminate(c));
    FreeInstance(c);
    fflush(stdout);
    dlclose(h); /* as FMI Library's hosts (fmuCheck) unload an FMU */
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
    char line[16384];
    while (fgets(line, sizeof line, f) != NULL) {
        line[strcspn(line, "\n")] = '\0';
        if (strncmp(line, "fmu ", 4) == 0) {
            memset(&s, 0, sizeof s);
            sscanf(line + 4, "%255s %4095s %4095s %255s", s.name, s.binary, s.resources, s.guid);
        } else if (strncmp(line, "steps ", 6) == 0) {
            sscanf(line + 6, "%d %lf", &s.steps, &s.h);
        } else if (strncmp(line, "input ", 6) == 0 && s.n_in < MAX_VARS) {
            sscanf(line + 6, "%u %lf %lf", &s.in[s.n_in], &s.a[s.n_in], &s.b[s.n_in]);
            s.n_in++;
        } else if (strncmp(line, "output ", 7) == 0 && s.n_out < MAX_VARS) {
            sscanf(line + 7, "%u", &s.out[s.n_out++]);
        } else if (strcmp(line, "run") == 0) {
            int rc = run(&s);
            if (rc != 0) return rc;
        }
    }
    fclose(f);
    return 0;
}
