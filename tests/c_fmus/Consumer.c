/* Consumer: shows, at each fmi2DoStep, the inputs it was given (one of each FMI type).
   k_seen = k, k_sum += k (Integer); lvl_seen = lvl (Enumeration Level); flag_seen = flag
   xor invert (Boolean; invert a Boolean parameter, start false); text_len = strlen(text),
   text_number = the decimal number at the end of text, -1 if none (Integer); time_out (Real)
   = the time reached. Inputs u (Real) and other (Enumeration Other) are there to be
   connected wrongly. */
#include <ctype.h>
#define N_REAL 2
#define N_INTEGER 8
#define N_BOOLEAN 3
#define N_STRING 1
#include "fmu_base.h"

enum { R_TIME, R_U };
enum { I_K, I_LVL, I_OTHER, I_K_SEEN, I_K_SUM, I_LVL_SEEN, I_TEXT_LEN, I_TEXT_NUMBER };
enum { B_FLAG, B_INVERT, B_FLAG_SEEN };
enum { S_TEXT };

static void model_start(Model *m) {
    m->i[I_LVL] = 1;
    m->i[I_OTHER] = 1;
    m->i[I_LVL_SEEN] = 1;
    m->i[I_TEXT_NUMBER] = -1;
}

static void model_outputs(Model *m) { (void)m; }

static fmi2Status model_step(Model *m, double t, double h) {
    const char *s = m->s[S_TEXT];
    size_t len = strlen(s), k = len;
    while (k > 0 && isdigit((unsigned char)s[k - 1])) k--;
    m->i[I_K_SEEN] = m->i[I_K];
    m->i[I_K_SUM] += m->i[I_K];
    m->i[I_LVL_SEEN] = m->i[I_LVL];
    m->b[B_FLAG_SEEN] = (m->b[B_FLAG] != m->b[B_INVERT]) ? fmi2True : fmi2False;
    m->i[I_TEXT_LEN] = (fmi2Integer)len;
    m->i[I_TEXT_NUMBER] = k < len ? atoi(s + k) : -1;
    m->r[R_TIME] = t + h;
    return fmi2OK;
}
