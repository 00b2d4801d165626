/*
 * The FMI 2.0 types and the types of the FMI functions, as both C libraries of an FMU need them: the loader
 * (fmu_loader.c, binaries/linux64/<model>.so) and the lean binding behind it (lean_binding.c, pmsm-binding.so).
 * Both forward calls to a library they load (dlsym) and so call every FMI function through a pointer of the type
 * below; both export the same functions. The layouts are FMI 2.0's (fmi2TypesPlatform.h, fmi2FunctionTypes.h,
 * "default" platform types); the build compiles each library with this header beside it (fmus/build.py).
 */
#ifndef PMSM_FMI2_BINDING_H
#define PMSM_FMI2_BINDING_H

#include <stddef.h>

typedef void* fmi2Component;
typedef void* fmi2ComponentEnvironment;
typedef void* fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char* fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void* (*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void*);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#define EXPORT __attribute__((visibility("default")))

/* -- pointers to the FMI functions (and to the project's counters), by signature -------------------------------- */
typedef fmi2Component (*instantiate_t)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions*,
                                       fmi2Boolean, fmi2Boolean);
typedef void (*free_t)(fmi2Component);
typedef fmi2Status (*debug_t)(fmi2Component, fmi2Boolean, size_t, const fmi2String[]);
typedef fmi2Status (*setup_t)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
typedef fmi2Status (*plain_t)(fmi2Component);

typedef fmi2Status (*get_real_t)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[]);
typedef fmi2Status (*set_real_t)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]);
typedef fmi2Status (*get_int_t)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]);
typedef fmi2Status (*set_int_t)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[]);
typedef fmi2Status (*get_str_t)(fmi2Component, const fmi2ValueReference[], size_t, fmi2String[]);
typedef fmi2Status (*set_str_t)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2String[]);

typedef fmi2Status (*state_t)(fmi2Component, fmi2FMUstate*);
typedef fmi2Status (*set_state_t)(fmi2Component, fmi2FMUstate);
typedef fmi2Status (*state_size_t)(fmi2Component, fmi2FMUstate, size_t*);
typedef fmi2Status (*serialize_t)(fmi2Component, fmi2FMUstate, fmi2Byte[], size_t);
typedef fmi2Status (*deserialize_t)(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate*);

typedef fmi2Status (*derivative_t)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2ValueReference[],
                                   size_t, const fmi2Real[], fmi2Real[]);
typedef fmi2Status (*input_derivatives_t)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                          const fmi2Real[]);
typedef fmi2Status (*output_derivatives_t)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                           fmi2Real[]);

typedef fmi2Status (*do_step_t)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);

typedef fmi2Status (*status_t)(fmi2Component, const fmi2StatusKind, fmi2Status*);
typedef fmi2Status (*real_status_t)(fmi2Component, const fmi2StatusKind, fmi2Real*);
typedef fmi2Status (*int_status_t)(fmi2Component, const fmi2StatusKind, fmi2Integer*);
typedef fmi2Status (*bool_status_t)(fmi2Component, const fmi2StatusKind, fmi2Boolean*);
typedef fmi2Status (*str_status_t)(fmi2Component, const fmi2StatusKind, fmi2String*);

/* pmsm_fmu_fast_calls, pmsm_fmu_compiled_calls (lean_binding.c) */
typedef unsigned long long (*calls_t)(fmi2Component);

/* pmsm_fmu_forwarded (fmu_loader.c) */
typedef void* (*forwarded_t)(const char*);

#endif
