/* Stopper: y (Real output) = the time reached, steps (Integer output) = the steps taken,
   until the time stop_at (Real parameter, start 0.5): an fmi2DoStep from t >= stop_at
   returns fmi2Discard with fmi2GetBooleanStatus(fmi2Terminated) true (the FMU asks to end
   the simulation) and fmi2GetRealStatus(fmi2LastSuccessfulTime) = t; with discard_only
   (Boolean parameter) it discards the step without asking to end. With inside (Boolean
   parameter), the step whose interval passes stop_at ends there, as the Modelica Reference FMU
   Stair does: y = stop_at, one more step counted, fmi2Discard with the termination asked and
   fmi2LastSuccessfulTime = stop_at. */
#include <math.h>
#define N_REAL 2
#define N_INTEGER 1
#define N_BOOLEAN 2
#define N_STRING 1
#include "fmu_base.h"

enum { R_Y, R_STOP_AT };
enum { I_STEPS };
enum { B_DISCARD_ONLY, B_INSIDE };

static void model_start(Model *m) { m->r[R_STOP_AT] = 0.5; }

static void model_outputs(Model *m) { (void)m; }

static fmi2Status model_step(Model *m, double t, double h) {
    double stop = m->r[R_STOP_AT];
    if (t >= stop - 1e-9 * fmax(1.0, fabs(stop))) {
        log_text(m, fmi2Discard, m->b[B_DISCARD_ONLY] ? "step refused" : "the stop time is reached");
        m->terminated = m->b[B_DISCARD_ONLY] ? fmi2False : fmi2True;
        return fmi2Discard;
    }
    if (m->b[B_INSIDE] && t + h > stop + 1e-9 * fmax(1.0, fabs(stop))) {
        m->r[R_Y] = stop;
        m->i[I_STEPS] += 1;
        m->time = stop;
        log_text(m, fmi2Discard, "the stop time is reached inside the step");
        m->terminated = fmi2True;
        return fmi2Discard;
    }
    m->r[R_Y] = t + h;
    m->i[I_STEPS] += 1;
    return fmi2OK;
}
