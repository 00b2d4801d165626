/*
 * The FMU's loader (Linux): binaries/linux64/<model>.so of the project's FMUs, in front of the binding
 * (pmsm-binding.so, the lean binding, beside it; else pythonfmu's pythonfmu-export.so). It references no Python
 * symbol, so any FMI 2.0 host loads it; why and how: fmus/README.md, "Hosts that are not Python".
 *
 * fmi2GetTypesPlatform and fmi2GetVersion are answered here. fmi2Instantiate brings the binding up once per
 * process: when the process has a Python already (Py_IsInitialized is found in its global scope: fmpy, any Python
 * host) the binding is loaded and nothing else is done, so a Python host runs exactly what it ran before. Where
 * it has none, a Python is looked for, in this order:
 *
 *   1. $PMSM_FMU_PYTHON: a Python interpreter, or a libpython shared library;
 *   2. the file resources/python.txt of the FMU (its first line: the same);
 *   3. the interpreter the FMU was built with (resources/build_python.txt, written by the build);
 *   4. python3 on the PATH.
 *
 * An interpreter is asked (one run of it) for its shared libpython, its home and its sys.path, and is taken only
 * if it has a shared libpython and numpy. Its libpython is loaded RTLD_GLOBAL, initialised with the interpreter
 * as program name and its home (so the standard library is found), its sys.path put in front of the embedded
 * one (so the site-packages that have numpy and numba are found), and the GIL released; then the binding is
 * loaded and pythonfmu sees an interpreter already running, as in a Python host (it neither starts nor
 * finalizes it). A libpython named directly is initialised with the home found above it (lib/pythonX.Y/os.py).
 * Where no Python is found, fmi2Instantiate logs one line through the host's logger (what was looked for, and
 * how to point at a Python) and returns NULL. Where the process's Python is not a Python program's, pythonfmu's
 * interpreter guard is reset at exit (release_wrapper), before pythonfmu's static destructors and, once the slaves'
 * compiled kernels have loaded numba's LLVM, before LLVM's (plan_release): the kernels are compiled in such a host
 * as in a Python program.
 *
 * Every other fmi2 function, and pmsm_fmu_fast_calls, pmsm_fmu_compiled_calls and pmsm_fmu_pulls, are the
 * binding's, called with the same arguments: the instance is the binding's own. pmsm_fmu_forwarded gives the FMI 3.0
 * layer the binding's own fmi2GetReal, fmi2SetReal and fmi2DoStep, which the loader's only forward, and
 * pmsm_fmu_known the same three without the binding's look-up of the instance, which the layer has made. Python's
 * C API is reached through dlsym only.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <link.h>
#include <pthread.h>
#include <spawn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>
#include <wchar.h>

extern char** environ;

#include "fmi2_binding.h"

#define ENV_PYTHON "PMSM_FMU_PYTHON"
#define USER_FILE "python.txt"
#define BUILT_FILE "build_python.txt"
static const char* const BINDINGS[] = {"pmsm-binding.so", "pythonfmu-export.so"};

/* what an interpreter is asked: its shared libpython, executable, home, whether it has numpy, its sys.path */
static const char QUERY[] =
    "import os, sys, sysconfig\n"
    "v = sysconfig.get_config_var\n"
    "names = [n for n in (v('INSTSONAME'), v('LDLIBRARY')) if n and '.so' in n]\n"
    "libs = [os.path.join(d, n) for n in names for d in (v('LIBDIR') or '', v('LIBPL') or '')]\n"
    "lib = next((p for p in libs if os.path.isfile(p)), '')\n"
    "try:\n"
    "    import numpy\n"
    "    has_numpy = 'yes'\n"
    "except Exception:\n"
    "    has_numpy = 'no'\n"
    "print('library', lib)\n"
    "print('executable', sys.executable)\n"
    "print('home', sys.base_prefix)\n"
    "print('numpy', has_numpy)\n"
    "for p in sys.path:\n"
    "    if p: print('path', p)\n";

/* -- the process's Python ---------------------------------------------------------------------------------- */
typedef struct {
    char library[PATH_MAX];
    char executable[PATH_MAX];
    char home[PATH_MAX];
    char* paths; /* the interpreter's sys.path, one a line */
} Python;

static void append(char* out, size_t size, const char* fmt, ...)
{
    size_t n = strlen(out);
    if (n + 1 >= size) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(out + n, size - n, fmt, ap);
    va_end(ap);
}

static int is_file(const char* path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

static int is_library(const char* path)
{
    const char* base = strrchr(path, '/');
    base = base ? base + 1 : path;
    return strncmp(base, "libpython", 9) == 0 && strstr(base, ".so") != NULL;
}

#include "own_directory.h" /* own_directory: the directory of this library */

/* the FMU's resources folder: from the URI the host gives (file:///x, file:/x, percent-encoded), else
 * ../../resources from this library */
static void resources_folder(const char* uri, char* out, size_t size)
{
    out[0] = '\0';
    if (uri != NULL && strncmp(uri, "file:", 5) == 0) {
        const char* p = uri + 5;
        if (strncmp(p, "///", 3) == 0) p += 2;
        else if (strncmp(p, "//localhost/", 12) == 0) p += 11;
        size_t n = 0;
        for (; *p && n + 1 < size; p++) {
            unsigned int c;
            if (p[0] == '%' && p[1] && p[2] && sscanf(p + 1, "%2x", &c) == 1) {
                out[n++] = (char)c;
                p += 2;
            } else {
                out[n++] = *p;
            }
        }
        out[n] = '\0';
        if (n > 0 && out[n - 1] != '/' && n + 1 < size) {
            out[n++] = '/';
            out[n] = '\0';
        }
        return;
    }
    own_directory(out, size);
    if (out[0]) append(out, size, "../../resources/");
}

/* the first line of a file (trimmed), or "" */
static void first_line(const char* path, char* out, size_t size)
{
    out[0] = '\0';
    FILE* f = fopen(path, "r");
    if (f == NULL) return;
    if (fgets(out, (int)size, f) == NULL) out[0] = '\0';
    fclose(f);
    size_t n = strlen(out);
    while (n > 0 && (out[n - 1] == '\n' || out[n - 1] == '\r' || out[n - 1] == ' ' || out[n - 1] == '\t'))
        out[--n] = '\0';
}

/* an executable named `name` on $PATH */
static int on_path(const char* name, char* out, size_t size)
{
    const char* path = getenv("PATH");
    if (path == NULL) return 0;
    while (*path) {
        const char* end = strchr(path, ':');
        size_t n = end ? (size_t)(end - path) : strlen(path);
        if (n > 0) {
            snprintf(out, size, "%.*s/%s", (int)n, path, name);
            if (is_file(out) && access(out, X_OK) == 0) return 1;
        }
        path += n + (end ? 1 : 0);
    }
    return 0;
}

/* run `interpreter -c QUERY` and read what it prints into `py`; 0, or -1 with the reason in `why` */
static int ask(const char* interpreter, Python* py, char* why, size_t size)
{
    int pipes[2];
    if (pipe(pipes) != 0) {
        snprintf(why, size, "cannot run it (%s)", strerror(errno));
        return -1;
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, pipes[1], 1);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", 0, 0);
    posix_spawn_file_actions_addclose(&actions, pipes[0]);
    posix_spawn_file_actions_addclose(&actions, pipes[1]);
    char* argv[] = {(char*)interpreter, "-c", (char*)QUERY, NULL};
    pid_t pid;
    int err = posix_spawn(&pid, interpreter, &actions, NULL, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    close(pipes[1]);
    if (err != 0) {
        close(pipes[0]);
        snprintf(why, size, "cannot run it (%s)", strerror(err));
        return -1;
    }
    size_t cap = 4096, len = 0;
    char* text = malloc(cap);
    ssize_t got;
    while (text != NULL && (got = read(pipes[0], text + len, cap - len - 1)) != 0) {
        if (got < 0) {
            if (errno == EINTR) continue;
            break;
        }
        len += (size_t)got;
        if (cap - len < 2) {
            char* bigger = realloc(text, cap *= 2);
            if (bigger == NULL) free(text);
            text = bigger;
        }
    }
    close(pipes[0]);
    int status = 0;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (text == NULL) {
        snprintf(why, size, "out of memory");
        return -1;
    }
    text[len] = '\0';
    int numpy = 0;
    py->library[0] = py->executable[0] = py->home[0] = '\0';
    free(py->paths);
    py->paths = calloc(len + 1, 1);
    for (char* line = strtok(text, "\n"); line != NULL; line = strtok(NULL, "\n")) {
        if (strncmp(line, "library ", 8) == 0) snprintf(py->library, sizeof py->library, "%s", line + 8);
        else if (strncmp(line, "executable ", 11) == 0)
            snprintf(py->executable, sizeof py->executable, "%s", line + 11);
        else if (strncmp(line, "home ", 5) == 0) snprintf(py->home, sizeof py->home, "%s", line + 5);
        else if (strcmp(line, "numpy yes") == 0) numpy = 1;
        else if (strncmp(line, "path ", 5) == 0 && py->paths != NULL) {
            strcat(py->paths, line + 5);
            strcat(py->paths, "\n");
        }
    }
    free(text);
    if (strstr(py->executable, "/") == NULL) {
        snprintf(why, size, "not a Python interpreter it can run");
        return -1;
    }
    if (!numpy) {
        snprintf(why, size, "has no numpy");
        return -1;
    }
    if (!py->library[0]) {
        snprintf(why, size, "has no shared libpython (a Python built with --enable-shared is needed)");
        return -1;
    }
    return 0;
}

/* a libpython named directly: its home, the first folder above it with lib/pythonX.Y/os.py */
static void home_of_library(const char* library, char* home, size_t size)
{
    home[0] = '\0';
    const char* base = strrchr(library, '/');
    base = base ? base + 1 : library;
    int major = 0, minor = 0;
    if (sscanf(base, "libpython%d.%d", &major, &minor) != 2) return;
    char dir[PATH_MAX], probe[PATH_MAX + 64];
    if (realpath(library, dir) == NULL) snprintf(dir, sizeof dir, "%s", library);
    char* slash;
    while ((slash = strrchr(dir, '/')) != NULL) {
        *slash = '\0';
        snprintf(probe, sizeof probe, "%s/lib/python%d.%d/os.py", dir[0] ? dir : "", major, minor);
        if (is_file(probe)) {
            snprintf(home, size, "%s", dir[0] ? dir : "/");
            return;
        }
    }
}

/* one candidate (an interpreter or a libpython): filled in `py`, or -1 with the reason in `why` */
static int candidate(const char* what, Python* py, char* why, size_t size)
{
    if (!is_file(what)) {
        snprintf(why, size, "no such file");
        return -1;
    }
    if (is_library(what)) {
        snprintf(py->library, sizeof py->library, "%s", what);
        py->executable[0] = '\0';
        home_of_library(what, py->home, sizeof py->home);
        free(py->paths);
        py->paths = NULL;
        return 0;
    }
    return ask(what, py, why, size);
}

/* Python's C API, reached through the loaded libpython */
typedef int (*is_initialized_t)(void);
typedef wchar_t* (*decode_t)(const char*, size_t*);
typedef void (*set_wide_t)(const wchar_t*);
typedef void (*initialize_t)(int);
typedef int (*run_t)(const char*);
typedef void* (*save_thread_t)(void);

/* "'<hex>'" literals of the lines of `paths`, as a Python list */
static char* path_list(const char* paths)
{
    size_t n = paths ? strlen(paths) : 0, lines = 1;
    for (size_t i = 0; i < n; i++) lines += paths[i] == '\n';
    char* out = malloc(2 * n + 64 * lines + 8);
    if (out == NULL) return NULL;
    strcpy(out, "[");
    const char* p = paths;
    while (p && *p) {
        const char* end = strchr(p, '\n');
        size_t k = end ? (size_t)(end - p) : strlen(p);
        strcat(out, "bytes.fromhex('");
        char* w = out + strlen(out);
        for (size_t i = 0; i < k; i++) w += sprintf(w, "%02x", (unsigned char)p[i]);
        strcpy(w, "').decode('utf-8', 'surrogateescape'), ");
        p += k + (end ? 1 : 0);
    }
    strcat(out, "]");
    return out;
}

/* load and start the Python `py` (RTLD_GLOBAL, its home and sys.path, the GIL released) */
static int start(const Python* py, char* why, size_t size)
{
    void* lib = dlopen(py->library, RTLD_NOW | RTLD_GLOBAL);
    if (lib == NULL) {
        snprintf(why, size, "cannot load %s (%s)", py->library, dlerror());
        return -1;
    }
    is_initialized_t is_initialized = (is_initialized_t)dlsym(lib, "Py_IsInitialized");
    decode_t decode = (decode_t)dlsym(lib, "Py_DecodeLocale");
    set_wide_t set_program = (set_wide_t)dlsym(lib, "Py_SetProgramName");
    set_wide_t set_home = (set_wide_t)dlsym(lib, "Py_SetPythonHome");
    initialize_t initialize = (initialize_t)dlsym(lib, "Py_InitializeEx");
    run_t run = (run_t)dlsym(lib, "PyRun_SimpleString");
    save_thread_t save_thread = (save_thread_t)dlsym(lib, "PyEval_SaveThread");
    if (!is_initialized || !decode || !initialize || !run || !save_thread) {
        snprintf(why, size, "%s is not a libpython 3 (missing functions)", py->library);
        return -1;
    }
    if (is_initialized()) return 0;
    /* kept for the interpreter's lifetime, as Py_SetProgramName and Py_SetPythonHome require */
    if (py->executable[0] && set_program) set_program(decode(py->executable, NULL));
    if (py->home[0] && set_home) set_home(decode(py->home, NULL));
    else if (py->home[0]) setenv("PYTHONHOME", py->home, 0); /* a Python without Py_SetPythonHome (3.15 on) */
    initialize(0); /* no signal handlers: the host's stay */
    if (!is_initialized()) {
        snprintf(why, size, "%s did not start", py->library);
        return -1;
    }
    char* list = path_list(py->paths);
    if (list != NULL) {
        const char* head = "import sys\n_p = ";
        const char* tail = "\nsys.path[:0] = [p for p in _p if p not in sys.path]\ndel _p\n";
        char* code = malloc(strlen(head) + strlen(list) + strlen(tail) + 1);
        if (code != NULL) {
            sprintf(code, "%s%s%s", head, list, tail);
            run(code);
            free(code);
        }
        free(list);
    }
    save_thread(); /* the GIL released: pythonfmu takes it per call, from any thread */
    return 0;
}

/* -- the binding ----------------------------------------------------------------------------------------- */
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static void* binding = NULL;
static int embedded = 0;        /* the process's Python is not a Python program's (started here, or by pythonfmu) */
static int release_planned = 0; /* release_wrapper registered with atexit */
static int release_after_llvm = 0; /* ... and again once numba's LLVM (llvmlite's library) was loaded */

typedef int (*gil_ensure_t)(void);
typedef void (*gil_release_t)(int);
typedef void* (*sys_get_t)(const char*);
typedef long (*length_t)(void*);

/* whether the process's Python is not a Python program's: none yet, not initialised, or sys.orig_argv empty
 * (an interpreter embedded in a host, as slave_support.release_at_exit tells it) */
static int python_is_embedded(void)
{
    is_initialized_t is_initialized = (is_initialized_t)dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (is_initialized == NULL || !is_initialized()) return 1;
    gil_ensure_t ensure = (gil_ensure_t)dlsym(RTLD_DEFAULT, "PyGILState_Ensure");
    gil_release_t release = (gil_release_t)dlsym(RTLD_DEFAULT, "PyGILState_Release");
    sys_get_t sys_get = (sys_get_t)dlsym(RTLD_DEFAULT, "PySys_GetObject");
    length_t length = (length_t)dlsym(RTLD_DEFAULT, "PyObject_Length");
    void (*clear)(void) = (void (*)(void))dlsym(RTLD_DEFAULT, "PyErr_Clear");
    if (!ensure || !release || !sys_get || !length || !clear) return 0;
    int gil = ensure();
    void* argv = sys_get("orig_argv");
    long n = argv ? length(argv) : 0;
    if (n < 0) clear();
    release(gil);
    return n <= 0;
}

/* at exit (or when this library is unloaded), before pythonfmu's C++ static destructors: reset pythonfmu's
 * interpreter guard through its own finalizePythonInterpreter, as slave_support.release_at_exit does in a Python
 * program; left alone, the guard is released by a static destructor and reset again by the library's ELF
 * destructor, a write into freed heap memory that aborts the process at exit ("free(): corrupted ...") */
static void release_wrapper(void)
{
    char dir[PATH_MAX], path[PATH_MAX + 64];
    own_directory(dir, sizeof dir);
    snprintf(path, sizeof path, "%s%s", dir, BINDINGS[1]);
    void* wrapper = dlopen(path, RTLD_LAZY | RTLD_NOLOAD);
    if (wrapper == NULL) return;
    void (*finalize)(void) = (void (*)(void))dlsym(wrapper, "finalizePythonInterpreter");
    if (finalize != NULL) finalize();
    dlclose(wrapper);
}

/* dl_iterate_phdr's callback: 1 at llvmlite's library (numba's LLVM), which has C++ static destructors */
static int is_llvm(struct dl_phdr_info* info, size_t size, void* data)
{
    (void)size;
    (void)data;
    const char* base = info->dlpi_name ? strrchr(info->dlpi_name, '/') : NULL;
    return base != NULL && strncmp(base + 1, "libllvmlite", 11) == 0;
}

/* where the process's Python is not a Python program's: release_wrapper at exit, registered after the first instance
 * (pythonfmu's library loaded, its static destructors registered) and again once numba's compiled kernels have
 * loaded llvmlite's library. Exit handlers run in the reverse order of their registration, so the second runs
 * before LLVM's static destructors: what release_wrapper may do then (an interpreter that pythonfmu started is
 * finalized with it, numba's objects freed through LLVM) finds LLVM still there, as at the end of a Python program,
 * which finalizes its interpreter before exit runs the handlers. Called after the calls in which the slaves build
 * their physics (and so load the kernels): fmi2Instantiate, fmi2ExitInitializationMode, fmi2Reset, fmi2Terminate,
 * fmi2FreeInstance. The second release finds the guard reset already and does nothing more. */
static void plan_release(void)
{
    pthread_mutex_lock(&lock);
    if (embedded && binding != NULL) {
        if (!release_planned) {
            release_planned = 1;
            atexit(release_wrapper);
        }
        if (!release_after_llvm && dl_iterate_phdr(is_llvm, NULL)) {
            release_after_llvm = 1;
            atexit(release_wrapper);
        }
    }
    pthread_mutex_unlock(&lock);
}

/* bring a Python into a process that has none; 0, or -1 with what was looked for in `why` */
static int bring_up_python(const char* resources, char* why, size_t size)
{
    is_initialized_t present = (is_initialized_t)dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (present != NULL) return 0; /* a Python host: its interpreter (pythonfmu starts it if it must) */
    Python py = {{0}, {0}, {0}, NULL};
    char what[PATH_MAX], reason[PATH_MAX + 256], file[PATH_MAX + 32];
    int tried = 0, ok = -1;
    snprintf(why, size, "no Python found for this FMU: looked for ");
    for (int step = 0; step < 4 && ok != 0; step++) {
        const char* label;
        const char* none = "no such file";
        what[0] = '\0';
        if (step == 0) {
            label = "$" ENV_PYTHON;
            none = "not set";
            const char* env = getenv(ENV_PYTHON);
            if (env != NULL) snprintf(what, sizeof what, "%s", env);
        } else if (step == 1) {
            label = "resources/" USER_FILE;
            snprintf(file, sizeof file, "%s%s", resources, USER_FILE);
            first_line(file, what, sizeof what);
        } else if (step == 2) {
            label = "the interpreter the FMU was built with";
            snprintf(file, sizeof file, "%s%s", resources, BUILT_FILE);
            first_line(file, what, sizeof what);
        } else {
            label = "python3 on PATH";
            none = "not found";
            if (!on_path("python3", what, sizeof what)) what[0] = '\0';
        }
        append(why, size, "%s%s", tried++ ? "; " : "", label);
        if (!what[0]) {
            append(why, size, " (%s)", none);
            continue;
        }
        reason[0] = '\0';
        ok = candidate(what, &py, reason, sizeof reason);
        if (ok == 0) {
            ok = start(&py, reason, sizeof reason);
            if (ok != 0) append(why, size, " (%s: %s)", what, reason);
        } else {
            append(why, size, " (%s: %s)", what, reason);
        }
    }
    free(py.paths);
    if (ok != 0)
        append(why, size, ". Set " ENV_PYTHON " to a Python 3 interpreter that has numpy (built with "
                          "--enable-shared), or to its libpython");
    return ok;
}

static int load_binding(const char* resources, char* why, size_t size)
{
    if (binding != NULL) return 0;
    embedded = python_is_embedded();
    if (bring_up_python(resources, why, size) != 0) return -1;
    char dir[PATH_MAX], path[PATH_MAX + 64];
    own_directory(dir, sizeof dir);
    why[0] = '\0';
    for (size_t i = 0; i < sizeof BINDINGS / sizeof BINDINGS[0]; i++) {
        snprintf(path, sizeof path, "%s%s", dir, BINDINGS[i]);
        if (!is_file(path)) continue;
        binding = dlopen(path, RTLD_NOW | RTLD_LOCAL);
        if (binding != NULL) return 0;
        snprintf(why, size, "cannot load %s: %s", path, dlerror());
        return -1;
    }
    snprintf(why, size, "no %s or %s beside %s", BINDINGS[0], BINDINGS[1], dir);
    return -1;
}

static void* fn(const char* name)
{
    return binding ? dlsym(binding, name) : NULL;
}

/* FORWARD(name, type, args...): the binding's function `name`, or fmi2Error where there is none */
#define FORWARD(name, type, ...)                                                                             \
    do {                                                                                                     \
        static type f = NULL;                                                                                \
        if (f == NULL) f = (type)fn(#name);                                                                  \
        if (f == NULL) return fmi2Error;                                                                     \
        return f(__VA_ARGS__);                                                                               \
    } while (0)

/* FORWARD, then plan_release(): a call in which a slave may have loaded the kernels (and so numba) */
#define FORWARD_PLANNED(name, type, ...)                                                                     \
    do {                                                                                                     \
        static type f = NULL;                                                                                \
        if (f == NULL) f = (type)fn(#name);                                                                  \
        if (f == NULL) return fmi2Error;                                                                     \
        fmi2Status status = f(__VA_ARGS__);                                                                  \
        plan_release();                                                                                      \
        return status;                                                                                       \
    } while (0)

/* -- the FMI functions ----------------------------------------------------------------------------------- */
EXPORT const char* fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char* fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    char resources[PATH_MAX], why[8192];
    resources_folder(fmuResourceLocation, resources, sizeof resources);
    pthread_mutex_lock(&lock);
    int ok = load_binding(resources, why, sizeof why);
    pthread_mutex_unlock(&lock);
    instantiate_t f = ok == 0 ? (instantiate_t)fn("fmi2Instantiate") : NULL;
    if (f == NULL) {
        if (ok == 0) snprintf(why, sizeof why, "the binding has no fmi2Instantiate");
        if (functions && functions->logger) { /* the message is the format: its '%' doubled */
            char message[2 * sizeof why];
            size_t n = 0;
            for (const char* p = why; *p && n + 2 < sizeof message; p++) {
                if (*p == '%') message[n++] = '%';
                message[n++] = *p;
            }
            message[n] = '\0';
            functions->logger(functions->componentEnvironment, instanceName ? instanceName : "", fmi2Error, "error",
                              message);
        }
        return NULL;
    }
    fmi2Component c = f(instanceName, fmuType, fmuGUID, fmuResourceLocation, functions, visible, loggingOn);
    if (c != NULL) plan_release(); /* pythonfmu's library is loaded now: its statics made */
    return c;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    free_t f = (free_t)fn("fmi2FreeInstance");
    if (f != NULL && c != NULL) f(c);
    if (c != NULL) plan_release();
}

/* pmsm_fmu_forwarded(name): the binding's own function `name`, where this loader's function of that name does nothing
 * but forward the call (FORWARD, above): fmi2GetReal, fmi2SetReal and fmi2DoStep, the calls of every step. The FMI
 * 3.0 layer in front of this loader (fmi3_layer.c) calls them so, one hop less a call, with the same arguments and
 * the same answer. NULL for any other name, and before the binding is loaded (the first fmi2Instantiate). */
EXPORT void* pmsm_fmu_forwarded(const char* name)
{
    static const char* const FORWARDED[] = {"fmi2GetReal", "fmi2SetReal", "fmi2DoStep"};
    for (size_t i = 0; name != NULL && i < sizeof FORWARDED / sizeof FORWARDED[0]; i++)
        if (strcmp(name, FORWARDED[i]) == 0) return fn(name);
    return NULL;
}

/* pmsm_fmu_known(name): the lean binding's fmi2GetReal, fmi2SetReal or fmi2DoStep without its look-up of the instance
 * (fmus/lean_binding.c, pmsm_fmu_known), for the FMI 3.0 layer, which has checked its own instance and holds the
 * binding's alive; NULL for any other name, without the lean binding, and before it is loaded */
EXPORT void* pmsm_fmu_known(const char* name)
{
    forwarded_t f = (forwarded_t)fn("pmsm_fmu_known");
    return f ? f(name) : NULL;
}

/* pmsm_fmu_fast_calls(instance): the lean binding's counter (fmus/lean_binding.c), 0 without one */
EXPORT unsigned long long pmsm_fmu_fast_calls(fmi2Component c)
{
    calls_t f = (calls_t)fn("pmsm_fmu_fast_calls");
    return f ? f(c) : 0;
}

/* pmsm_fmu_compiled_calls(instance): the lean binding's count of the calls served with no Python, 0 without one */
EXPORT unsigned long long pmsm_fmu_compiled_calls(fmi2Component c)
{
    calls_t f = (calls_t)fn("pmsm_fmu_compiled_calls");
    return f ? f(c) : 0;
}

/* pmsm_fmu_pulls(instance): the lean binding's count of the compiled step's buffers handed back to Python, 0
 * without one */
EXPORT unsigned long long pmsm_fmu_pulls(fmi2Component c)
{
    calls_t f = (calls_t)fn("pmsm_fmu_pulls");
    return f ? f(c) : 0;
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[])
{
    FORWARD(fmi2SetDebugLogging, debug_t, c, on, n, categories);
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                                      fmi2Boolean stopDefined, fmi2Real stop)
{
    FORWARD(fmi2SetupExperiment, setup_t, c, tolDefined, tol, start, stopDefined, stop);
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) { FORWARD(fmi2EnterInitializationMode, plain_t, c); }
EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    FORWARD_PLANNED(fmi2ExitInitializationMode, plain_t, c);
}
EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    FORWARD_PLANNED(fmi2Terminate, plain_t, c);
}
EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    FORWARD_PLANNED(fmi2Reset, plain_t, c);
}
EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { FORWARD(fmi2CancelStep, plain_t, c); }

EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    FORWARD(fmi2GetReal, get_real_t, c, vr, nvr, value);
}
EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    FORWARD(fmi2SetReal, set_real_t, c, vr, nvr, value);
}
EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    FORWARD(fmi2GetInteger, get_int_t, c, vr, nvr, value);
}
EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    FORWARD(fmi2GetBoolean, get_int_t, c, vr, nvr, value);
}
EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    FORWARD(fmi2GetString, get_str_t, c, vr, nvr, value);
}
EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Integer value[])
{
    FORWARD(fmi2SetInteger, set_int_t, c, vr, nvr, value);
}
EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Boolean value[])
{
    FORWARD(fmi2SetBoolean, set_int_t, c, vr, nvr, value);
}
EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                const fmi2String value[])
{
    FORWARD(fmi2SetString, set_str_t, c, vr, nvr, value);
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state) { FORWARD(fmi2GetFMUstate, state_t, c, state); }
EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    FORWARD(fmi2SetFMUstate, set_state_t, c, state);
}
EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    FORWARD(fmi2FreeFMUstate, state_t, c, state);
}
EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size)
{
    FORWARD(fmi2SerializedFMUstateSize, state_size_t, c, state, size);
}
EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    FORWARD(fmi2SerializeFMUstate, serialize_t, c, state, bytes, size);
}
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state)
{
    FORWARD(fmi2DeSerializeFMUstate, deserialize_t, c, bytes, size, state);
}

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[], size_t nu,
                                               const fmi2ValueReference known[], size_t nk, const fmi2Real dv[],
                                               fmi2Real df[])
{
    FORWARD(fmi2GetDirectionalDerivative, derivative_t, c, unknown, nu, known, nk, dv, df);
}
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[])
{
    FORWARD(fmi2SetRealInputDerivatives, input_derivatives_t, c, vr, nvr, order, value);
}
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[])
{
    FORWARD(fmi2GetRealOutputDerivatives, output_derivatives_t, c, vr, nvr, order, value);
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean flag)
{
    FORWARD(fmi2DoStep, do_step_t, c, t, h, flag);
}

EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* value)
{
    FORWARD(fmi2GetStatus, status_t, c, s, value);
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value)
{
    FORWARD(fmi2GetRealStatus, real_status_t, c, s, value);
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* value)
{
    FORWARD(fmi2GetIntegerStatus, int_status_t, c, s, value);
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value)
{
    FORWARD(fmi2GetBooleanStatus, bool_status_t, c, s, value);
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* value)
{
    FORWARD(fmi2GetStringStatus, str_status_t, c, s, value);
}
