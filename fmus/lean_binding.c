/*
 * The project's lean FMI 2.0 binding (Linux): the FMU's binaries/linux64/<model>.so in front of pythonfmu's
 * own library (pythonfmu-export.so, beside it). Why and what it does: fmus/README.md, "The lean binding";
 * docs/performance.md.
 *
 * Every FMI function is pythonfmu's, forwarded, except the three of the per-step path once the slave has
 * offered itself (DriveSlave._offer calls pmsm_fmu_offer, on this thread, when the slave is made: inside the
 * forwarded fmi2Instantiate or fmi2Reset) and fmi2ExitInitializationMode has succeeded:
 *
 *   fmi2GetReal    the slave's attributes read directly (what DriveSlave.get_real returns: the same objects,
 *                  the same doubles), when every value reference names a Real and the slave is not stale;
 *   fmi2SetReal    the Real inputs written into the instance dict (what DriveSlave.set_real does), when every
 *                  value reference names a Real input;
 *   fmi2DoStep     the slave's do_step (unchecked) called directly, when the communication point continues the
 *                  last step, the step is no longer than the slave's _max_step and the FMU is in step mode.
 *
 * The compiled step (fmus/README.md, "The compiled step"): where the slave has one (its compiled_step returns the
 * address of a C function, a numba cfunc of pmsm_ev.kernels.fmu, and of its three buffers), the three calls above
 * run no Python: fmi2SetReal writes the inputs into the buffers, fmi2DoStep calls the C function, fmi2GetReal reads
 * the buffers (every value reference in a buffer: compiled_slots). The buffers then hold the slave's values
 * (c_owned); before any Python runs on the slave (a forwarded call, a refusal asked, a value not in a buffer, a step
 * the C function declines) the binding calls its compiled_pull, which copies them back into its attributes, and
 * asks compiled_step again (which fills the buffers from them) at the next compiled call. A step the C function
 * declines (0) or fails (-1: a kernel raised, the vectors restored) is the slave's Python do_step, below.
 * pmsm_fmu_compiled_calls(instance) counts the calls served so (a part of pmsm_fmu_fast_calls).
 *
 * FMI 2.0's checks (DriveSlave.refusal: the state machine, non-finite Real inputs, a communication point that
 * does not continue the last step, a step too long): before it forwards fmi2SetupExperiment,
 * fmi2EnterInitializationMode, fmi2ExitInitializationMode, fmi2DoStep or fmi2SetReal, and where a check of the
 * direct path above fails (a non-finite value, a time that does not continue, a step too long, not in step
 * mode), the binding asks the slave's refusal; a call refused is not made: its line goes to the host's logger
 * and its status (fmi2Error; fmi2Discard for a step too long) is returned. The direct path keeps where the
 * last step ended in C and writes it into the slave (_next_time) before it asks, and when it stops.
 *
 * Anything else, or anything that fails on the way, goes to pythonfmu's function with the same arguments, so
 * that the errors, their log messages and their statuses are pythonfmu's: a get or set that would fail is
 * never half done here (all checks come first; a failing attribute read is cleared and the whole call
 * forwarded, reads have no side effect). An exception in do_step is handed to the slave (defer), which
 * raises it again from pythonfmu's fmi2DoStep, forwarded: pythonfmu logs and returns it as it always did.
 * Messages the slave queued during a direct step are flushed by a zero-length fmi2GetReal, forwarded
 * (pythonfmu drains the queue after every call, with its own debug-logging filter).
 * fmi2GetRealStatus (the last successful time) and fmi2GetBooleanStatus (terminated) are answered here
 * for every step, direct or forwarded, as pythonfmu answers them.
 *
 * pmsm_fmu_fast_calls(instance) is the number of calls this instance served on the direct path (fmi2GetReal,
 * fmi2SetReal and fmi2DoStep completed here, not forwarded): a test of the binding's contract reads it
 * (tests/test_lean_binding.py), so that a binding that falls back to pythonfmu's path fails it rather than only
 * losing its speed. Counted per instance, without the GIL on the compiled path: FMI calls on one instance are serial
 * (the standard's rule for a master), so each count is exact in a host of several instances and threads.
 *
 * An instance the binding did not make, or has freed (NULL, a stale pointer): every function returns fmi2Error
 * (fmi2FreeInstance and the counters do nothing) without touching it: the binding keeps the instances it made in
 * a table (enlist, delist) and looks each call's up there first (live), with no lock on the look-up. There is no
 * logger to tell: the host's callbacks belong to the instance. pmsm_fmu_known gives fmi2GetReal, fmi2SetReal and
 * fmi2DoStep without the look-up to the FMI 3.0 layer (fmi3_layer.c), which looks its own instance up at every call
 * and holds this binding's alive while it is.
 *
 * The compiled step's buffers: the slave offers their addresses with their lengths (compiled_step); a slot that
 * falls outside its buffer keeps the compiled path off for that slave (its Python step runs), never a write out
 * of bounds.
 *
 * Checked against pythonfmu 0.6.5 to 0.7.0 (pmsm_ev_fmus.slave_support.WRAPPER_CHECKED): the log queue it
 * drains after every call, its fmi2DoStep's handling of a slave's do_step; the build refuses another version.
 *
 * Python's limited API (3.8), as pythonfmu's library: no libpython is linked; the host process provides it.
 */
#define Py_LIMITED_API 0x03080000
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_binding.h"

#define INNER_LIBRARY "pythonfmu-export.so"

/* -- pythonfmu's library ------------------------------------------------------------------------------ */
static void* inner_library = NULL;

static void* inner(const char* name)
{
    if (inner_library == NULL) {
        Dl_info self;
        if (!dladdr((void*)&inner, &self) || self.dli_fname == NULL) return NULL;
        size_t n = strlen(self.dli_fname);
        char* path = malloc(n + sizeof(INNER_LIBRARY) + 1);
        if (path == NULL) return NULL;
        memcpy(path, self.dli_fname, n + 1);
        char* slash = strrchr(path, '/');
        strcpy(slash ? slash + 1 : path, INNER_LIBRARY);
        inner_library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
        free(path);
        if (inner_library == NULL) return NULL;
    }
    return dlsym(inner_library, name);
}

/* forward(name, type, args...): pythonfmu's function `name` of type `type`, or fmi2Error if missing (or if `c` is
 * not an instance of this binding's) */
#define FORWARD(name, type, ...)                                                                             \
    do {                                                                                                     \
        static type fn = NULL;                                                                               \
        if (!live(c)) return fmi2Error;                                                                      \
        to_python_gil((Instance*)c);                                                                         \
        if (fn == NULL) fn = (type)inner(#name);                                                             \
        if (fn == NULL) return fmi2Error;                                                                    \
        return fn(__VA_ARGS__);                                                                              \
    } while (0)

/* -- an instance ------------------------------------------------------------------------------------------ */
/* the compiled step: int step(double* io, double* a, double* b, double t, double h), pmsm_ev.kernels.fmu:
 * 1 taken, 0 declined (nothing changed), -1 a kernel raised (nothing changed) */
typedef int (*c_step_t)(double*, double*, double*, double, double);
/* The constants shared with the slaves, defined once in pmsm_ev_fmus.slave_support.BINDING_CONSTANTS and given
 * by the build as -D definitions:
 *   COMPILED_BUFFER       a slot's buffer stride (buffer b's element i is COMPILED_BUFFER * b + i);
 *   LIVE_SLOT             a slot of a value read through the slave's Python while the buffers hold its values
 *                         (compiled_live): its getter reads the physics object's buffers, not the slave's
 *                         attributes, so no compiled_pull is needed first;
 *   CONTINUITY_TOLERANCE  a communication point continues the last step within this share of its size ...
 *   TIME_ULPS             ... plus this many ulps of the time. */
#if !defined(COMPILED_BUFFER) || !defined(LIVE_SLOT) || !defined(CONTINUITY_TOLERANCE) || !defined(TIME_ULPS)
#error "compile with the -D definitions of pmsm_ev_fmus.slave_support.BINDING_CONSTANTS (pmsm_ev_fmus.build does)"
#endif

typedef struct {
    fmi2Component inner;        /* pythonfmu's instance */
    int ready;                  /* the direct path is on (offered, initialised, no failure handed over) */
    double last_successful_time;
    int terminated;
    unsigned long long fast_calls; /* calls served on the direct path (pmsm_fmu_fast_calls) */
    /* the slave's offer (strong references, released with the GIL held) */
    PyObject* slave;            /* the pythonfmu.Fmi2Slave */
    PyObject* attributes;       /* its instance dict */
    PyObject* do_step;          /* its bound do_step */
    PyObject* defer;            /* defer(exc): make its do_step raise exc (from pythonfmu's fmi2DoStep) */
    PyObject* log_queue;        /* the list pythonfmu drains after every call */
    PyObject* stale_name;       /* "_stale" */
    Py_ssize_t n;               /* value references 0 .. n-1 */
    PyObject** names;           /* by value reference: the attribute of a Real variable, or NULL */
    unsigned char* inputs;      /* by value reference: 1 for a Real input */
    PyObject* offer;            /* the tuple offered (keeps the names alive) */
    PyObject* refusal;          /* its refusal(call, *args): None or (status, message) */
    double next_time;           /* where the last direct step ended (NAN: any communication point) */
    double last_step;           /* its size */
    double max_step;            /* the slave's _max_step (read at fmi2ExitInitializationMode) */
    fmi2CallbackFunctions callbacks; /* the host's (a copy), for the refusals' log lines */
    char* name;                 /* the instance name */
    /* the compiled step (the slave's compiled_step, compiled_pull, compiled_slots) */
    PyObject* compiled;         /* compiled_step(): None, or (step, io, a, b) addresses and (io, a, b) lengths */
    PyObject* pull;             /* compiled_pull(): the slave's attributes from the buffers */
    long* slots;                /* by value reference: COMPILED_BUFFER * buffer + index, LIVE_SLOT, or -1 (read in
                                 * Python after compiled_pull) */
    c_step_t c_step;            /* the C function */
    double* buffers[3];         /* io, a, b */
    Py_ssize_t lengths[3];      /* their lengths (doubles) */
    int c_owned;                /* the buffers hold the slave's inputs, outputs and state; its attributes are behind */
    int c_off;                  /* compiled_step said None: not asked again until re-armed (direct_path) */
    unsigned long long compiled_calls; /* calls served with no Python (pmsm_fmu_compiled_calls) */
    unsigned long long pulls;   /* the buffers handed back to the slave's Python (pmsm_fmu_pulls) */
} Instance;

/* -- the instances this binding made: the instance table (instance_table.h) ------------------------------ */
#include "instance_table.h"

/* the offer made on this thread during the forwarded fmi2EnterInitializationMode */
static __thread PyObject* pending_offer = NULL;

/* pmsm_fmu_offer((slave, attributes, do_step, defer, log_queue, names, inputs, refusal[, compiled_step,
 * compiled_pull, slots])), called by the slave through ctypes.PyDLL (the GIL held): names, inputs and slots are
 * sequences by value reference (a str or None; a truth value; an int, -1 for none). Returns 0, or -1 if the offer
 * is malformed (then nothing is kept). */
EXPORT int pmsm_fmu_offer(PyObject* offer)
{
    if (!PyTuple_Check(offer) || (PyTuple_Size(offer) != 8 && PyTuple_Size(offer) != 11)) return -1;
    Py_XDECREF(pending_offer);
    Py_INCREF(offer);
    pending_offer = offer;
    return 0;
}

static void sync_time(Instance* w);

static void to_python(Instance* w);

static void drop_offer(Instance* w)
{
    w->ready = 0;
    if (w->offer == NULL) return;
    to_python(w);
    sync_time(w);
    free(w->names);
    free(w->inputs);
    free(w->slots);
    w->names = NULL;
    w->inputs = NULL;
    w->slots = NULL;
    w->c_owned = 0;
    w->c_step = NULL;
    Py_CLEAR(w->compiled);
    Py_CLEAR(w->pull);
    Py_CLEAR(w->offer);
    Py_CLEAR(w->slave);
    Py_CLEAR(w->attributes);
    Py_CLEAR(w->do_step);
    Py_CLEAR(w->defer);
    Py_CLEAR(w->log_queue);
    Py_CLEAR(w->stale_name);
    Py_CLEAR(w->refusal);
    w->n = 0;
}

static void drop_offer_gil(Instance* w)
{
    if (w->offer == NULL && pending_offer == NULL) return;
    PyGILState_STATE gil = PyGILState_Ensure();
    drop_offer(w);
    Py_CLEAR(pending_offer);
    PyGILState_Release(gil);
}

/* take this thread's pending offer (GIL held); a malformed one is dropped (the direct path stays off) */
static void take_offer(Instance* w)
{
    PyObject* offer = pending_offer;
    pending_offer = NULL;
    drop_offer(w);
    if (offer == NULL) return;
    PyObject* names = PyTuple_GetItem(offer, 5);
    PyObject* inputs = PyTuple_GetItem(offer, 6);
    Py_ssize_t n = names ? PySequence_Size(names) : -1;
    if (n < 0 || PySequence_Size(inputs) != n) goto bad;
    w->names = calloc((size_t)n + 1, sizeof(PyObject*));
    w->inputs = calloc((size_t)n + 1, 1);
    if (w->names == NULL || w->inputs == NULL) goto bad;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject* name = PySequence_GetItem(names, i);
        PyObject* input = PySequence_GetItem(inputs, i);
        int is_input = input ? PyObject_IsTrue(input) : -1;
        Py_XDECREF(input);
        if (name == NULL || is_input < 0) {
            Py_XDECREF(name);
            goto bad;
        }
        if (name != Py_None && !PyUnicode_Check(name)) {
            Py_DECREF(name);
            goto bad;
        }
        if (name != Py_None) {
            w->names[i] = name; /* borrowed below: `offer` keeps the sequence, which keeps the str */
            w->inputs[i] = (unsigned char)(is_input > 0);
        }
        Py_DECREF(name);
    }
    w->n = n;
    w->offer = offer;
    w->slave = PyTuple_GetItem(offer, 0);
    w->attributes = PyTuple_GetItem(offer, 1);
    w->do_step = PyTuple_GetItem(offer, 2);
    w->defer = PyTuple_GetItem(offer, 3);
    w->log_queue = PyTuple_GetItem(offer, 4);
    w->refusal = PyTuple_GetItem(offer, 7);
    Py_XINCREF(w->refusal);
    Py_XINCREF(w->slave);
    Py_XINCREF(w->attributes);
    Py_XINCREF(w->do_step);
    Py_XINCREF(w->defer);
    Py_XINCREF(w->log_queue);
    if (PyTuple_Size(offer) == 11 && PyTuple_GetItem(offer, 8) != Py_None) {
        PyObject* slots = PyTuple_GetItem(offer, 10);
        if (slots == NULL || PySequence_Size(slots) != n) goto bad;
        w->slots = calloc((size_t)n + 1, sizeof(long));
        if (w->slots == NULL) goto bad;
        for (Py_ssize_t i = 0; i < n; i++) {
            PyObject* item = PySequence_GetItem(slots, i);
            long slot = item ? PyLong_AsLong(item) : -1;
            Py_XDECREF(item);
            if (PyErr_Occurred() || (slot < 0 && slot != -1 && slot != LIVE_SLOT)) goto bad;
            w->slots[i] = w->names[i] != NULL ? slot : -1;
        }
        w->compiled = PyTuple_GetItem(offer, 8);
        w->pull = PyTuple_GetItem(offer, 9);
        Py_XINCREF(w->compiled);
        Py_XINCREF(w->pull);
        if (w->compiled == NULL || w->pull == NULL) goto bad;
    }
    w->stale_name = PyUnicode_FromString("_stale");
    if (!w->slave || !w->attributes || !PyDict_Check(w->attributes) || !w->do_step || !w->defer || !w->log_queue
        || !PyList_Check(w->log_queue) || !w->stale_name || !w->refusal)
        goto bad;
    return;
bad:
    PyErr_Clear();
    if (w->offer == NULL) {
        free(w->names);
        free(w->inputs);
        free(w->slots);
        w->names = NULL;
        w->inputs = NULL;
        w->slots = NULL;
        w->n = 0;
        Py_DECREF(offer);
    } else {
        drop_offer(w);
    }
}

/* pmsm_fmu_fast_calls(instance): the fmi2GetReal, fmi2SetReal and fmi2DoStep calls of this instance served on the
 * direct path since it was instantiated (0 for NULL or an instance not this binding's) */
EXPORT unsigned long long pmsm_fmu_fast_calls(fmi2Component c)
{
    return live(c) ? ((Instance*)c)->fast_calls : 0;
}

/* pmsm_fmu_compiled_calls(instance): the fmi2GetReal, fmi2SetReal and fmi2DoStep calls of this instance served
 * with no Python at all (the compiled step on the slave's buffers), a part of pmsm_fmu_fast_calls (0 for NULL) */
EXPORT unsigned long long pmsm_fmu_compiled_calls(fmi2Component c)
{
    return live(c) ? ((Instance*)c)->compiled_calls : 0;
}

/* pmsm_fmu_pulls(instance): how many times the binding handed the compiled step's buffers back to the slave's Python
 * (compiled_pull: a forwarded call, a refusal asked, a value read that is neither in the buffers nor live, a step
 * the C function declines), after which the next compiled call refills them (compiled_step) (0 for NULL) */
EXPORT unsigned long long pmsm_fmu_pulls(fmi2Component c)
{
    return live(c) ? ((Instance*)c)->pulls : 0;
}

/* -- the compiled step: who holds the slave's values ------------------------------------------------------ */
/* the slave's attributes from the buffers, before any Python runs on it (GIL held) */
static void to_python(Instance* w)
{
    if (!w->c_owned) return;
    w->c_owned = 0;
    w->pulls++;
    PyObject* done = w->pull ? PyObject_CallObject(w->pull, NULL) : NULL;
    if (done == NULL) { /* cannot happen with the project's slaves; the compiled path stays off */
        PyErr_Clear();
        w->c_off = 1;
    }
    Py_XDECREF(done);
}

static void to_python_gil(Instance* w)
{
    if (!w->c_owned) return;
    PyGILState_STATE gil = PyGILState_Ensure();
    to_python(w);
    PyGILState_Release(gil);
}

/* the buffers filled from the slave (its compiled_step), if it has a compiled step now: 1, else 0 */
static int to_compiled(Instance* w)
{
    if (w->c_owned) return 1;
    if (w->compiled == NULL || w->c_off) return 0;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject* answer = PyObject_CallObject(w->compiled, NULL);
    int ok = 0;
    if (answer != NULL && PyTuple_Check(answer) && PyTuple_Size(answer) == 7) {
        void* step = PyLong_AsVoidPtr(PyTuple_GetItem(answer, 0));
        for (int i = 0; i < 3; i++) {
            w->buffers[i] = (double*)PyLong_AsVoidPtr(PyTuple_GetItem(answer, i + 1));
            w->lengths[i] = PyLong_AsSsize_t(PyTuple_GetItem(answer, i + 4));
        }
        ok = !PyErr_Occurred() && step != NULL && w->buffers[0] && w->buffers[1] && w->buffers[2];
        for (Py_ssize_t i = 0; ok && i < w->n; i++) { /* every slot inside its buffer */
            long slot = w->slots[i];
            long b = slot / COMPILED_BUFFER;
            ok = slot < 0 || (b < 3 && slot % COMPILED_BUFFER < w->lengths[b]);
        }
        if (ok) w->c_step = (c_step_t)step;
    }
    Py_XDECREF(answer);
    PyErr_Clear();
    w->c_owned = ok;
    w->c_off = !ok;
    PyGILState_Release(gil);
    return ok;
}

/* the double of value reference vr in the buffers (slot >= 0) */
static inline double* slot_of(Instance* w, fmi2ValueReference vr)
{
    long slot = w->slots[vr];
    return w->buffers[slot / COMPILED_BUFFER] + slot % COMPILED_BUFFER;
}

/* -- FMI 2.0's checks (DriveSlave.refusal) ------------------------------------------------------------- */
/* write where the last direct step ended into the slave (_next_time, _last_step), GIL held */
static void sync_time(Instance* w)
{
    if (w->slave == NULL) return;
    PyObject* next = isnan(w->next_time) ? (Py_INCREF(Py_None), Py_None) : PyFloat_FromDouble(w->next_time);
    PyObject* last = PyFloat_FromDouble(w->last_step);
    if (next == NULL || last == NULL || PyObject_SetAttrString(w->slave, "_next_time", next) != 0
        || PyObject_SetAttrString(w->slave, "_last_step", last) != 0)
        PyErr_Clear();
    Py_XDECREF(next);
    Py_XDECREF(last);
}

/* the slave's number attribute `name`, or `otherwise` (GIL held) */
static double slave_number(Instance* w, const char* name, double otherwise)
{
    PyObject* v = w->slave ? PyObject_GetAttrString(w->slave, name) : NULL;
    double x = v ? PyFloat_AsDouble(v) : otherwise;
    Py_XDECREF(v);
    if (PyErr_Occurred()) {
        PyErr_Clear();
        x = otherwise;
    }
    return x;
}

/* ask the slave's refusal(call, *args) (args: a new tuple, stolen; GIL held): -1 when the call is allowed (or
 * nothing can be asked), else the status to return, its line logged through the host's logger */
static int refused(Instance* w, const char* call, PyObject* args)
{
    int status = -1;
    if (w->refusal == NULL || args == NULL) {
        Py_XDECREF(args);
        PyErr_Clear();
        return -1;
    }
    to_python(w);
    sync_time(w);
    PyObject* name = PyUnicode_FromString(call);
    PyObject* full = name ? PyTuple_New(PyTuple_Size(args) + 1) : NULL;
    if (full != NULL) {
        PyTuple_SetItem(full, 0, name);
        name = NULL;
        for (Py_ssize_t i = 0; i < PyTuple_Size(args); i++) {
            PyObject* item = PyTuple_GetItem(args, i);
            Py_INCREF(item);
            PyTuple_SetItem(full, i + 1, item);
        }
    }
    Py_XDECREF(name);
    Py_DECREF(args);
    PyObject* answer = full ? PyObject_Call(w->refusal, full, NULL) : NULL;
    Py_XDECREF(full);
    if (answer != NULL && PyTuple_Check(answer) && PyTuple_Size(answer) == 2) {
        long code = PyLong_AsLong(PyTuple_GetItem(answer, 0));
        PyObject* text = PyUnicode_AsUTF8String(PyTuple_GetItem(answer, 1));
        if (!PyErr_Occurred() && text != NULL) {
            status = (int)code;
            if (w->callbacks.logger != NULL)
                w->callbacks.logger(w->callbacks.componentEnvironment, w->name ? w->name : "", (fmi2Status)status,
                                    status == fmi2Discard ? "logStatusDiscard" : "logStatusError", "%s",
                                    PyBytes_AsString(text));
        }
        Py_XDECREF(text);
    }
    Py_XDECREF(answer);
    PyErr_Clear();
    return status;
}

/* refused() for a call of no argument, with the GIL taken here */
static int refused_plain(Instance* w, const char* call)
{
    if (w->refusal == NULL) return -1;
    PyGILState_STATE gil = PyGILState_Ensure();
    int status = refused(w, call, PyTuple_New(0));
    PyGILState_Release(gil);
    return status;
}

static int refused_step(Instance* w, double t, double h)
{
    if (w->refusal == NULL) return -1;
    PyGILState_STATE gil = PyGILState_Ensure();
    int status = refused(w, "fmi2DoStep", Py_BuildValue("(dd)", t, h));
    PyGILState_Release(gil);
    return status;
}

static int refused_set(Instance* w, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (w->refusal == NULL) return -1;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject* refs = PyList_New((Py_ssize_t)nvr);
    PyObject* values = PyList_New((Py_ssize_t)nvr);
    for (size_t i = 0; refs && values && i < nvr; i++) {
        PyList_SetItem(refs, (Py_ssize_t)i, PyLong_FromUnsignedLong(vr[i]));
        PyList_SetItem(values, (Py_ssize_t)i, PyFloat_FromDouble(value[i]));
    }
    PyObject* args = (refs && values && !PyErr_Occurred()) ? PyTuple_Pack(2, refs, values) : NULL;
    Py_XDECREF(refs);
    Py_XDECREF(values);
    int status = refused(w, "fmi2SetReal", args);
    PyGILState_Release(gil);
    return status;
}

/* refused() for a typed get or set (fmi2GetReal, fmi2SetInteger, ...) on its value references: the slave's refusal
 * of one that names no variable or one of another type (GIL taken here) */
static int refused_refs(Instance* w, const char* call, const fmi2ValueReference vr[], size_t nvr)
{
    if (w->refusal == NULL) return -1;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject* refs = PyList_New((Py_ssize_t)nvr);
    for (size_t i = 0; refs && i < nvr; i++) PyList_SetItem(refs, (Py_ssize_t)i, PyLong_FromUnsignedLong(vr[i]));
    PyObject* args = (refs && !PyErr_Occurred()) ? PyTuple_Pack(1, refs) : NULL;
    Py_XDECREF(refs);
    int status = refused(w, call, args);
    PyGILState_Release(gil);
    return status;
}

/* a typed get or set other than of Reals: refused (refused_refs), else forwarded */
#define CHECKED_FORWARD(name, type, ...)                                                                     \
    do {                                                                                                     \
        if (!live(c)) return fmi2Error;                                                                      \
        int refusal = refused_refs(W, #name, vr, nvr);                                                       \
        if (refusal >= 0) return (fmi2Status)refusal;                                                        \
        FORWARD(name, type, __VA_ARGS__);                                                                    \
    } while (0)

/* the direct path on, after fmi2ExitInitializationMode or fmi2SetFMUstate succeeded: when the slave is in step
 * mode; a step from any time; the slave's longest step (GIL taken here) */
static void direct_path(Instance* w)
{
    w->ready = 0;
    w->next_time = NAN;
    w->last_step = 0.0;
    w->c_off = 0; /* the slave is asked again for its compiled step */
    if (w->offer == NULL) return;
    PyGILState_STATE gil = PyGILState_Ensure();
    to_python(w);
    PyObject* mode = PyObject_GetAttrString(w->slave, "_in_step_mode");
    int in_step_mode = mode ? PyObject_IsTrue(mode) : 0;
    Py_XDECREF(mode);
    PyErr_Clear();
    w->max_step = slave_number(w, "_max_step", INFINITY);
    if (isnan(w->max_step)) w->max_step = INFINITY;
    w->ready = in_step_mode > 0;
    PyGILState_Release(gil);
}

/* -- the FMI functions ---------------------------------------------------------------------------------- */
/* free an instance that is out of the table (delist) */
static void fmi2FreeInstance_unlisted(Instance* w)
{
    drop_offer_gil(w);
    free_t fn = (free_t)inner("fmi2FreeInstance");
    if (fn != NULL) fn(w->inner);
    free(w->name);
    free(w);
}

EXPORT const char* fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char* fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    instantiate_t fn = (instantiate_t)inner("fmi2Instantiate");
    if (fn == NULL) {
        if (functions && functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Fatal, "error",
                              "cannot load " INNER_LIBRARY " beside the FMU's library: %s", dlerror());
        return NULL;
    }
    Instance* w = calloc(1, sizeof(Instance));
    if (w == NULL) return NULL;
    w->inner = fn(instanceName, fmuType, fmuGUID, fmuResourceLocation, functions, visible, loggingOn);
    if (!Py_IsInitialized()) { /* pythonfmu could not start an interpreter */
        if (w->inner != NULL) {
            free_t release = (free_t)inner("fmi2FreeInstance");
            if (release != NULL) release(w->inner);
        }
        free(w);
        return NULL;
    }
    PyGILState_STATE gil = PyGILState_Ensure();
    if (w->inner == NULL) {
        Py_CLEAR(pending_offer);
        PyGILState_Release(gil);
        free(w);
        return NULL;
    }
    take_offer(w); /* the slave made in this call offered itself */
    PyGILState_Release(gil);
    w->last_successful_time = NAN;
    w->next_time = NAN;
    w->max_step = INFINITY;
    if (functions != NULL) w->callbacks = *functions;
    w->name = strdup(instanceName ? instanceName : "");
    if (!enlist(w)) {
        if (functions && functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "more than %d instances at once", LIVE_INSTANCES);
        fmi2FreeInstance_unlisted(w);
        return NULL;
    }
    return w;
}

#define W ((Instance*)c)

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    if (delist(c)) fmi2FreeInstance_unlisted(W); /* (not this binding's instance, or freed already: nothing) */
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[])
{
    FORWARD(fmi2SetDebugLogging, debug_t, W->inner, on, n, categories);
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                                      fmi2Boolean stopDefined, fmi2Real stop)
{
    if (!live(c)) return fmi2Error;
    int status = refused_plain(W, "fmi2SetupExperiment");
    if (status >= 0) return (fmi2Status)status;
    FORWARD(fmi2SetupExperiment, setup_t, W->inner, tolDefined, tol, start, stopDefined, stop);
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    if (!live(c)) return fmi2Error;
    static plain_t fn = NULL;
    if (fn == NULL) fn = (plain_t)inner("fmi2EnterInitializationMode");
    if (fn == NULL) return fmi2Error;
    int refusal = refused_plain(W, "fmi2EnterInitializationMode");
    if (refusal >= 0) return (fmi2Status)refusal;
    W->ready = 0;
    return fn(W->inner);
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    if (!live(c)) return fmi2Error;
    static plain_t fn = NULL;
    if (fn == NULL) fn = (plain_t)inner("fmi2ExitInitializationMode");
    if (fn == NULL) return fmi2Error;
    int refusal = refused_plain(W, "fmi2ExitInitializationMode");
    if (refusal >= 0) return (fmi2Status)refusal;
    fmi2Status status = fn(W->inner);
    if (status == fmi2OK || status == fmi2Warning) direct_path(W);
    else W->ready = 0;
    return status;
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    if (!live(c)) return fmi2Error;
    to_python_gil(W);
    if (W->ready) { /* the direct path stops: the slave learns where the last step ended */
        PyGILState_STATE gil = PyGILState_Ensure();
        sync_time(W);
        PyGILState_Release(gil);
        W->ready = 0;
    }
    FORWARD(fmi2Terminate, plain_t, W->inner);
}

EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    if (!live(c)) return fmi2Error;
    static plain_t fn = NULL;
    if (fn == NULL) fn = (plain_t)inner("fmi2Reset");
    if (fn == NULL) return fmi2Error;
    drop_offer_gil(W); /* pythonfmu makes a new slave: it offers itself, in this call */
    W->last_successful_time = NAN;
    W->terminated = 0;
    fmi2Status status = fn(W->inner);
    PyGILState_STATE gil = PyGILState_Ensure();
    take_offer(W);
    PyGILState_Release(gil);
    return status;
}

static fmi2Status forward_get_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    FORWARD(fmi2GetReal, get_real_t, W->inner, vr, nvr, value);
}

/* fmi2GetReal on pythonfmu's path, unless the slave refuses its value references (refused_refs) */
static fmi2Status checked_get_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    int status = refused_refs(W, "fmi2GetReal", vr, nvr);
    return status >= 0 ? (fmi2Status)status : forward_get_real(c, vr, nvr, value);
}

static fmi2Status forward_set_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                   const fmi2Real value[])
{
    FORWARD(fmi2SetReal, set_real_t, W->inner, vr, nvr, value);
}

/* the slave's Real attribute of value reference vr into *value (GIL held): 1, or 0 with a Python error set */
static int read_attribute(Instance* w, fmi2ValueReference vr, fmi2Real* value)
{
    PyObject* v = PyObject_GetAttr(w->slave, w->names[vr]);
    if (v == NULL) return 0;
    *value = PyFloat_AsDouble(v);
    Py_DECREF(v);
    return !(*value == -1.0 && PyErr_Occurred());
}

/* fmi2GetReal of an instance known to be live (the checked entry below; pmsm_fmu_known) */
static fmi2Status get_real_known(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    Instance* w = W;
    if (!w->ready || nvr == 0) return checked_get_real(c, vr, nvr, value);
    for (size_t i = 0; i < nvr; i++)
        if ((Py_ssize_t)vr[i] >= w->n || w->names[vr[i]] == NULL) return checked_get_real(c, vr, nvr, value);
    if (w->c_owned) { /* the buffers hold the values: read there, if every one is there (or live) */
        size_t i = 0;
        int live = 0;
        while (i < nvr && (w->slots[vr[i]] >= 0 || w->slots[vr[i]] == LIVE_SLOT)) live |= w->slots[vr[i++]] < 0;
        if (i == nvr && !live) {
            for (i = 0; i < nvr; i++) value[i] = *slot_of(w, vr[i]);
            w->fast_calls++;
            w->compiled_calls++;
            return fmi2OK;
        }
        if (i == nvr) { /* some live: their getters on the buffers, the GIL held; the buffers stay the slave's */
            PyGILState_STATE gil = PyGILState_Ensure();
            int ok = 1;
            for (i = 0; ok && i < nvr; i++) {
                if (w->slots[vr[i]] >= 0) value[i] = *slot_of(w, vr[i]);
                else ok = read_attribute(w, vr[i], &value[i]);
            }
            if (!ok) PyErr_Clear();
            else w->fast_calls++;
            PyGILState_Release(gil);
            if (ok) return fmi2OK; /* else: the slave's attributes, as below */
        }
    }
    PyGILState_STATE gil = PyGILState_Ensure();
    to_python(w);
    PyObject* stale = PyObject_GetAttr(w->slave, w->stale_name);
    int is_stale = stale ? PyObject_IsTrue(stale) : -1;
    Py_XDECREF(stale);
    int ok = is_stale == 0;
    for (size_t i = 0; ok && i < nvr; i++) ok = read_attribute(w, vr[i], &value[i]);
    if (!ok) PyErr_Clear();
    else w->fast_calls++;
    PyGILState_Release(gil);
    return ok ? fmi2OK : forward_get_real(c, vr, nvr, value);
}

EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (!live(c)) return fmi2Error;
    return get_real_known(c, vr, nvr, value);
}

static fmi2Status checked_set_real(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                   const fmi2Real value[])
{
    int status = refused_set(W, vr, nvr, value);
    return status >= 0 ? (fmi2Status)status : forward_set_real(c, vr, nvr, value);
}

/* fmi2SetReal of an instance known to be live (the checked entry below; pmsm_fmu_known) */
static fmi2Status set_real_known(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Real value[])
{
    Instance* w = W;
    if (!w->ready || nvr == 0) return checked_set_real(c, vr, nvr, value);
    for (size_t i = 0; i < nvr; i++)
        if ((Py_ssize_t)vr[i] >= w->n || !w->inputs[vr[i]] || !isfinite(value[i]))
            return checked_set_real(c, vr, nvr, value);
    if (w->slots != NULL) { /* into the buffers, if every input is there and the slave has its compiled step */
        size_t i = 0;
        while (i < nvr && w->slots[vr[i]] >= 0) i++;
        if (i == nvr && to_compiled(w)) {
            for (i = 0; i < nvr; i++) *slot_of(w, vr[i]) = value[i];
            w->fast_calls++;
            w->compiled_calls++;
            return fmi2OK;
        }
    }
    PyGILState_STATE gil = PyGILState_Ensure();
    to_python(w);
    int ok = 1;
    for (size_t i = 0; ok && i < nvr; i++) {
        PyObject* v = PyFloat_FromDouble(value[i]);
        ok = v != NULL && PyDict_SetItem(w->attributes, w->names[vr[i]], v) == 0;
        Py_XDECREF(v);
    }
    if (!ok) { /* out of memory: the inputs set so far are set again by pythonfmu's call */
        PyErr_Clear();
    } else {
        w->fast_calls++;
    }
    PyGILState_Release(gil);
    return ok ? fmi2OK : forward_set_real(c, vr, nvr, value);
}

EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (!live(c)) return fmi2Error;
    return set_real_known(c, vr, nvr, value);
}

EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    CHECKED_FORWARD(fmi2GetInteger, get_int_t, W->inner, vr, nvr, value);
}
EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    CHECKED_FORWARD(fmi2GetBoolean, get_int_t, W->inner, vr, nvr, value);
}
EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    CHECKED_FORWARD(fmi2GetString, get_str_t, W->inner, vr, nvr, value);
}
EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Integer value[])
{
    CHECKED_FORWARD(fmi2SetInteger, set_int_t, W->inner, vr, nvr, value);
}
EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Boolean value[])
{
    CHECKED_FORWARD(fmi2SetBoolean, set_int_t, W->inner, vr, nvr, value);
}
EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                const fmi2String value[])
{
    CHECKED_FORWARD(fmi2SetString, set_str_t, W->inner, vr, nvr, value);
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    FORWARD(fmi2GetFMUstate, state_t, W->inner, state);
}
EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    if (!live(c)) return fmi2Error;
    static set_state_t fn = NULL;
    if (fn == NULL) fn = (set_state_t)inner("fmi2SetFMUstate");
    if (fn == NULL) return fmi2Error;
    to_python_gil(W);
    fmi2Status status = fn(W->inner, state);
    if (status == fmi2OK || status == fmi2Warning) direct_path(W); /* in step mode if the state is; any time */
    return status;
}
EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    FORWARD(fmi2FreeFMUstate, state_t, W->inner, state);
}
EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size)
{
    FORWARD(fmi2SerializedFMUstateSize, state_size_t, W->inner, state, size);
}
EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    FORWARD(fmi2SerializeFMUstate, serialize_t, W->inner, state, bytes, size);
}
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state)
{
    FORWARD(fmi2DeSerializeFMUstate, deserialize_t, W->inner, bytes, size, state);
}

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[], size_t nu,
                                               const fmi2ValueReference known[], size_t nk, const fmi2Real dv[],
                                               fmi2Real df[])
{
    FORWARD(fmi2GetDirectionalDerivative, derivative_t, W->inner, unknown, nu, known, nk, dv, df);
}
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[])
{
    FORWARD(fmi2SetRealInputDerivatives, input_derivatives_t, W->inner, vr, nvr, order, value);
}
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[])
{
    FORWARD(fmi2GetRealOutputDerivatives, output_derivatives_t, W->inner, vr, nvr, order, value);
}

static fmi2Status forward_do_step(Instance* w, fmi2Real t, fmi2Real h, fmi2Boolean flag)
{
    static do_step_t fn = NULL;
    if (fn == NULL) fn = (do_step_t)inner("fmi2DoStep");
    if (fn == NULL) return fmi2Error;
    to_python_gil(w);
    fmi2Status status = fn(w->inner, t, h, flag);
    if (status == fmi2OK) w->last_successful_time = t + h;
    if (status == fmi2Discard) {
        w->last_successful_time = t;
        w->terminated = 1;
    }
    return status;
}

/* a step the slave refuses: its status (a step discarded ends at t, the run is not terminated) */
static fmi2Status refuse_step(Instance* w, double t, int status)
{
    if (status == fmi2Discard) w->last_successful_time = t;
    return (fmi2Status)status;
}

/* fmi2DoStep of an instance known to be live (the checked entry below; pmsm_fmu_known) */
static fmi2Status do_step_known(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean flag)
{
    Instance* w = W;
    if (!w->ready) {
        int status = refused_step(w, t, h);
        return status >= 0 ? refuse_step(w, t, status) : forward_do_step(w, t, h, flag);
    }
    if (!(h <= w->max_step) || !isfinite(t)
        || (!isnan(w->next_time) && fabs(t - w->next_time) > CONTINUITY_TOLERANCE * w->last_step
                                     + TIME_ULPS * 2.220446049250313e-16 * fabs(t))) {
        int status = refused_step(w, t, h);
        if (status >= 0) return refuse_step(w, t, status);
    }
    if (w->slots != NULL && to_compiled(w)) { /* the compiled step, unless it declines */
        int done = w->c_step(w->buffers[0], w->buffers[1], w->buffers[2], t, h);
        if (done == 1) {
            w->fast_calls++;
            w->compiled_calls++;
            w->last_successful_time = t + h;
            w->next_time = t + h;
            w->last_step = h;
            return fmi2OK;
        }
        if (done < 0) w->c_off = 1; /* a kernel raised: the Python step raises it; not compiled again until re-armed */
    }
    PyGILState_STATE gil = PyGILState_Ensure();
    to_python(w);
    PyObject* pt = PyFloat_FromDouble(t);
    PyObject* ph = PyFloat_FromDouble(h);
    PyObject* result = (pt && ph) ? PyObject_CallFunctionObjArgs(w->do_step, pt, ph, NULL) : NULL;
    Py_XDECREF(pt);
    Py_XDECREF(ph);
    if (result == NULL) { /* hand the exception to the slave: pythonfmu's fmi2DoStep raises and reports it */
        PyObject *type, *exc, *traceback;
        PyErr_Fetch(&type, &exc, &traceback);
        PyErr_NormalizeException(&type, &exc, &traceback);
        if (exc != NULL && traceback != NULL) PyException_SetTraceback(exc, traceback);
        PyObject* deferred = exc ? PyObject_CallFunctionObjArgs(w->defer, exc, NULL) : NULL;
        Py_XDECREF(deferred);
        PyErr_Clear();
        Py_XDECREF(type);
        Py_XDECREF(exc);
        Py_XDECREF(traceback);
        drop_offer(w); /* the direct path stays off for this slave */
        PyGILState_Release(gil);
        return forward_do_step(w, t, h, flag);
    }
    int ok = PyObject_IsTrue(result);
    Py_DECREF(result);
    Py_ssize_t queued = PyList_Size(w->log_queue);
    PyErr_Clear();
    w->fast_calls++;
    PyGILState_Release(gil);
    if (ok > 0) {
        w->last_successful_time = t + h;
        w->next_time = t + h;
        w->last_step = h;
    } else {
        w->last_successful_time = t;
        w->terminated = 1;
    }
    if (queued > 0) { /* pythonfmu drains the queue after any call: an empty read */
        fmi2ValueReference none = 0;
        fmi2Real nothing = 0.0;
        forward_get_real(c, &none, 0, &nothing);
    }
    return ok > 0 ? fmi2OK : fmi2Discard;
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean flag)
{
    if (!live(c)) return fmi2Error;
    return do_step_known(c, t, h, flag);
}

/* pmsm_fmu_known(name): fmi2GetReal, fmi2SetReal or fmi2DoStep without their look-up of the instance in the table
 * (live), for a caller that holds an instance of this binding's alive and has checked its own handle already: the
 * FMI 3.0 layer (fmi3_layer.c), whose every call looks its instance up first and which frees the FMI 2.0 instance
 * only in fmi3FreeInstance, after taking its own out of its table. The same arguments, the same answers, every
 * other check the same. NULL for any other name. */
EXPORT void* pmsm_fmu_known(const char* name)
{
    if (name == NULL) return NULL;
    if (strcmp(name, "fmi2GetReal") == 0) return (void*)get_real_known;
    if (strcmp(name, "fmi2SetReal") == 0) return (void*)set_real_known;
    if (strcmp(name, "fmi2DoStep") == 0) return (void*)do_step_known;
    return NULL;
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    FORWARD(fmi2CancelStep, plain_t, W->inner);
}

EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* value)
{
    FORWARD(fmi2GetStatus, status_t, W->inner, s, value);
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value)
{
    if (!live(c)) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = W->last_successful_time;
        return fmi2OK;
    }
    FORWARD(fmi2GetRealStatus, real_status_t, W->inner, s, value);
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* value)
{
    FORWARD(fmi2GetIntegerStatus, int_status_t, W->inner, s, value);
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value)
{
    if (!live(c)) return fmi2Error;
    if (s == fmi2Terminated) {
        *value = W->terminated ? 1 : 0;
        return fmi2OK;
    }
    FORWARD(fmi2GetBooleanStatus, bool_status_t, W->inner, s, value);
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* value)
{
    FORWARD(fmi2GetStringStatus, str_status_t, W->inner, s, value);
}
