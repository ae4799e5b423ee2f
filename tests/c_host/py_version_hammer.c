/* A thread that calls CPython's Py_GetVersion without pause, loaded into a Python process by
 * tests/_version_race.py (ctypes, RTLD_GLOBAL: Py_GetVersion is the process's own). Py_GetVersion
 * formats its text into a static buffer at every call, writing '\0' at its start first (glibc's
 * vsnprintf): a reader of that buffer in another thread sees "" now and then. */
#include <pthread.h>

extern const char *Py_GetVersion(void);

static int stop;
static pthread_t thread;
static long calls;

static void *hammer(void *arg)
{
    (void)arg;
    while (!__atomic_load_n(&stop, __ATOMIC_RELAXED)) {
        Py_GetVersion();
        calls++;
    }
    return NULL;
}

int hammer_start(void)
{
    return pthread_create(&thread, NULL, hammer, NULL);
}

long hammer_stop(void)
{
    __atomic_store_n(&stop, 1, __ATOMIC_RELAXED);
    pthread_join(thread, NULL);
    return calls;
}
