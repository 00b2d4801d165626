/* A minimal FMI 3.0 co-simulation host in C, for tests/test_fmi3.py: no libpython linked, nothing of Python in its
 * process but what an FMU brings itself (as tests/c_host.c for FMI 2.0).
 *
 *   c_host3 SPEC
 *
 * SPEC is a text file of blocks, one per FMU, each run to its end before the next:
 *
 *   fmu <name> <binary .so> <resource folder> <instantiation token>
 *   steps <n> <h>
 *   clock <vr> <every>     (optional: instantiate with eventModeUsed and tick the clock before every <every>-th step:
 *                           fmi3EnterEventMode, fmi3SetClock, fmi3UpdateDiscreteStates, fmi3EnterStepMode)
 *   input <vr> <a> <b>     (a Float64 input: a + b k before step k)
 *   output <vr>            (a Float64 output printed after each step)
 *   run
 *
 * For each FMU it prints "fmu <name> <fmi3GetVersion>", then one line per step: "<k> <status of the tick and the
 * step> <status of the get> <output values %.17g>...", then "calls <fast> <compiled>": the lean binding's
 * pmsm_fmu_fast_calls and pmsm_fmu_compiled_calls of the instance (0 0 where the FMU's library has none).
 * What the FMU logs goes to stdout as "log <status> <category> <message>". Exit code 0 when every FMU ran
 * (whatever its statuses), 2 when a binary cannot be loaded, 3 when fmi3InstantiateCoSimulation returns NULL. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3FunctionTypes.h"

#define MAX_VARS 64

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    printf("log %d %s %s\n", (int)status, category ? category : "", message ? message : "");
    fflush(stdout);
}

typedef unsigned long long (*calls_t)(fmi3Instance);

#define GET(handle, name) ((name##TYPE*)dlsym(handle, #name))

static int run(const char* name, const char* binary, const char* resources, const char* token, int steps, double h,
               int clocked, fmi3ValueReference clock, int every, int n_in, const fmi3ValueReference* in_vr,
               const double* a, const double* b, int n_out, const fmi3ValueReference* out_vr)
{
    void* lib = dlopen(binary, RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        printf("cannot load %s: %s\n", binary, dlerror());
        return 2;
    }
    fmi3Instance c = GET(lib, fmi3InstantiateCoSimulation)(name, token, resources, fmi3False, fmi3False,
                                                           clocked ? fmi3True : fmi3False, fmi3False, NULL, 0, NULL,
                                                           logger, NULL);
    printf("fmu %s %s\n", name, GET(lib, fmi3GetVersion)());
    if (c == NULL) return 3;
    fmi3Status s = GET(lib, fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    s = s > fmi3Warning ? s : GET(lib, fmi3ExitInitializationMode)(c);
    printf("initialised %d\n", (int)s);
    fmi3Float64 in[MAX_VARS], out[MAX_VARS];
    for (int k = 0; k < steps; k++) {
        for (int i = 0; i < n_in; i++) in[i] = a[i] + b[i] * k;
        fmi3Status step = n_in ? GET(lib, fmi3SetFloat64)(c, in_vr, (size_t)n_in, in, (size_t)n_in) : fmi3OK;
        if (clocked && k % every == 0 && step <= fmi3Warning) { /* the tick */
            fmi3Boolean on = fmi3True, need, term, nominals, values, defined;
            fmi3Float64 next;
            step = GET(lib, fmi3EnterEventMode)(c);
            if (step <= fmi3Warning) step = GET(lib, fmi3SetClock)(c, &clock, 1, &on);
            if (step <= fmi3Warning)
                step = GET(lib, fmi3UpdateDiscreteStates)(c, &need, &term, &nominals, &values, &defined, &next);
            if (step <= fmi3Warning) step = GET(lib, fmi3EnterStepMode)(c);
        }
        fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
        fmi3Float64 last = 0.0;
        if (step <= fmi3Warning)
            step = GET(lib, fmi3DoStep)(c, k * h, h, fmi3True, &event, &terminate, &early, &last);
        fmi3Status got = GET(lib, fmi3GetFloat64)(c, out_vr, (size_t)n_out, out, (size_t)n_out);
        printf("%d %d %d", k, (int)step, (int)got);
        for (int i = 0; i < n_out; i++) printf(" %.17g", out[i]);
        printf("\n");
    }
    calls_t fast = (calls_t)dlsym(lib, "pmsm_fmu_fast_calls"), compiled = (calls_t)dlsym(lib, "pmsm_fmu_compiled_calls");
    printf("calls %llu %llu\n", fast ? fast(c) : 0ULL, compiled ? compiled(c) : 0ULL);
    printf("terminate %d\n", (int)GET(lib, fmi3Terminate)(c));
    GET(lib, fmi3FreeInstance)(c);
    fflush(stdout);
    return 0;
}

int main(int argc, char** argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: c_host3 SPEC\n");
        return 1;
    }
    FILE* f = fopen(argv[1], "r");
    if (f == NULL) {
        fprintf(stderr, "cannot open %s\n", argv[1]);
        return 1;
    }
    char line[4096], name[256] = "", binary[2048] = "", resources[2048] = "", token[256] = "";
    int steps = 0, n_in = 0, n_out = 0, clocked = 0, every = 1, code = 0;
    double h = 0.0, a[MAX_VARS], b[MAX_VARS];
    fmi3ValueReference in_vr[MAX_VARS], out_vr[MAX_VARS], clock = 0;
    while (fgets(line, sizeof line, f) != NULL && code == 0) {
        unsigned vr;
        if (sscanf(line, "fmu %255s %2047s %2047s %255s", name, binary, resources, token) == 4) {
            n_in = n_out = clocked = 0;
        } else if (sscanf(line, "steps %d %lf", &steps, &h) == 2) {
        } else if (sscanf(line, "clock %u %d", &vr, &every) == 2) {
            clocked = 1, clock = vr;
        } else if (n_in < MAX_VARS && sscanf(line, "input %u %lf %lf", &vr, &a[n_in], &b[n_in]) == 3) {
            in_vr[n_in++] = vr;
        } else if (n_out < MAX_VARS && sscanf(line, "output %u", &vr) == 1) {
            out_vr[n_out++] = vr;
        } else if (strncmp(line, "run", 3) == 0) {
            code = run(name, binary, resources, token, steps, h, clocked, clock, every, n_in, in_vr, a, b, n_out,
                       out_vr);
        }
    }
    fclose(f);
    return code;
}
