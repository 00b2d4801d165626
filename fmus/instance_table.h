/* The instances a library made and has not freed: the one instance table of the lean binding (lean_binding.c)
 * and the FMI 3.0 layer (fmi3_layer.c), each with its own (a static table per library that includes this).
 *
 * Every FMI function looks its instance up first (``live``, no lock); fmi2/3Instantiate puts it in (``enlist``),
 * fmi2/3FreeInstance takes it out (``delist``). A NULL, freed or foreign pointer is not in the table: the caller
 * answers it with an error status and touches nothing. A host that frees an instance while another thread still
 * calls it breaks FMI's rules; the table catches a freed or foreign pointer, not that race. */
#ifndef PMSM_INSTANCE_TABLE_H
#define PMSM_INSTANCE_TABLE_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>

/* at most this many at once (a host asking for more gets NULL from its instantiate function, with a log line) */
#define LIVE_INSTANCES 4096
static _Atomic(void*) live_table[LIVE_INSTANCES];
static atomic_size_t live_top; /* entries in use are below it */
static pthread_mutex_t live_lock = PTHREAD_MUTEX_INITIALIZER;

/* whether c is an instance this library made and has not freed */
static int live(const void* c)
{
    if (c == NULL) return 0;
    size_t n = atomic_load_explicit(&live_top, memory_order_acquire);
    for (size_t i = 0; i < n; i++)
        if (atomic_load_explicit(&live_table[i], memory_order_relaxed) == c) return 1;
    return 0;
}

/* put w in the table: 1, or 0 where it is full */
static int enlist(void* w)
{
    int done = 0;
    pthread_mutex_lock(&live_lock);
    size_t n = atomic_load_explicit(&live_top, memory_order_relaxed);
    for (size_t i = 0; i < n && !done; i++)
        if (atomic_load_explicit(&live_table[i], memory_order_relaxed) == NULL) {
            atomic_store_explicit(&live_table[i], w, memory_order_release);
            done = 1;
        }
    if (!done && n < LIVE_INSTANCES) {
        atomic_store_explicit(&live_table[n], w, memory_order_release);
        atomic_store_explicit(&live_top, n + 1, memory_order_release);
        done = 1;
    }
    pthread_mutex_unlock(&live_lock);
    return done;
}

/* take w out of the table: 1, or 0 where it was not in it (NULL never is: a free slot holds NULL) */
static int delist(const void* w)
{
    int found = 0;
    if (w == NULL) return 0;
    pthread_mutex_lock(&live_lock);
    size_t n = atomic_load_explicit(&live_top, memory_order_relaxed);
    for (size_t i = 0; i < n && !found; i++)
        if (atomic_load_explicit(&live_table[i], memory_order_relaxed) == w) {
            atomic_store_explicit(&live_table[i], NULL, memory_order_release);
            found = 1;
        }
    pthread_mutex_unlock(&live_lock);
    return found;
}

#endif
