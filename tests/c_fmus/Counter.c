/* Counter: counts its steps, and says it in every FMI type.
   count (Integer output) += step_by (Integer parameter, start 1) at every fmi2DoStep;
   level (Enumeration Level output) = 1 + count mod 3 (Low, Mid, High);
   odd (Boolean output) = count is odd; label (String output) = prefix (String parameter,
   start "n") (its first 40 characters) followed by count in decimal; time_out (Real output) = the time reached. */
#define N_REAL 1
#define N_INTEGER 3
#define N_BOOLEAN 1
#define N_STRING 2
#include "fmu_base.h"

enum { R_TIME };
enum { I_COUNT, I_STEP_BY, I_LEVEL };
enum { B_ODD };
enum { S_LABEL, S_PREFIX };

static void model_start(Model *m) {
    m->r[R_TIME] = 0.0;
    m->i[I_COUNT] = 0;
    m->i[I_STEP_BY] = 1;
    snprintf(m->s[S_PREFIX], STRING_SIZE, "n");
    model_outputs(m);
}

static void model_outputs(Model *m) {
    int n = m->i[I_COUNT];
    m->i[I_LEVEL] = 1 + ((n % 3) + 3) % 3;
    m->b[B_ODD] = (n % 2 != 0) ? fmi2True : fmi2False;
    snprintf(m->s[S_LABEL], STRING_SIZE, "%.40s%d", m->s[S_PREFIX], n);
}

static fmi2Status model_step(Model *m, double t, double h) {
    m->i[I_COUNT] += m->i[I_STEP_BY];
    m->r[R_TIME] = t + h;
    model_outputs(m);
    return fmi2OK;
}
