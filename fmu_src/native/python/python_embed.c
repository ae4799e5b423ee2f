/* See python_embed.h. */
#define _GNU_SOURCE
#include "python_embed.h"

#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <unistd.h>

PyApi py;
static pthread_mutex_t boot_lock = PTHREAD_MUTEX_INITIALIZER; /* this copy's statics below */

/* The interpreter of the process is started once, whichever copy of this launcher gets there
 * first: every FMU carries its own copy of the library (loaded RTLD_LOCAL, with its own statics
 * and its own boot_lock), and two copies starting (or one checking while another starts) the one
 * CPython of the process crash it. What all copies share is the libpython they load: an exclusive
 * flock(2) on that file, taken around "is it running? else start it", orders them (it orders the
 * start-ups of other processes too, a few milliseconds each, which is harmless). Where the lock
 * cannot be had (no file, a file system without locks) the start goes on unordered, as before. */
static int lock_interpreter_start(const void *libpython_symbol)
{
    Dl_info info;
    if (!dladdr(libpython_symbol, &info) || !info.dli_fname) return -1;
    int fd = open(info.dli_fname, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return -1;
    while (flock(fd, LOCK_EX) != 0) {
        if (errno != EINTR) {
            close(fd);
            return -1;
        }
    }
    return fd;
}

static void unlock_interpreter_start(int fd)
{
    if (fd < 0) return;
    flock(fd, LOCK_UN);
    close(fd);
}
int python_ready = 0;    /* py.* resolved and an interpreter running */
char python_report[4096]; /* what was tried, for the error message */
PyObject *boot = NULL;    /* globals of pogofmu_boot.py (compiled once per process) */

static void report(const char *fmt, ...)
{
    size_t n = strlen(python_report);
    if (n + 2 >= sizeof python_report) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(python_report + n, sizeof python_report - n, fmt, ap);
    va_end(ap);
}

/* Resolve every function from `handle`; on failure name the first missing symbol. */
static int resolve(void *handle, const char **missing)
{
#define RESOLVE(ret, name, args)                                  \
    *(void **)&py.name = dlsym(handle, #name);                    \
    if (!py.name) { *missing = #name; return 0; }
    PY_FUNCTIONS(RESOLVE)
#undef RESOLVE
    py.none = (PyObject *)dlsym(handle, "_Py_NoneStruct");
    if (!py.none) { *missing = "_Py_NoneStruct"; return 0; }
#define RESOLVE_FLAG(name) py.name = (int *)dlsym(handle, #name);
    PY_FLAGS(RESOLVE_FLAG)
#undef RESOLVE_FLAG
    return 1;
}

/* The version of the CPython whose Py_GetVersion is `get_version` (its library `handle`, or
 * RTLD_DEFAULT), as text ("3.11.7") in `text`: from its Py_Version constant (CPython 3.11 and
 * newer), else from Py_GetVersion, which the caller calls only under the interpreter-start lock
 * (lock_interpreter_start): Py_GetVersion formats its text into a static buffer at every call,
 * whose first byte glibc's vsnprintf sets to '\0' before it writes, so a thread reading it while
 * another calls it can read "" — the launchers of several FMUs instantiated at once from threads
 * took the host's CPython 3.11.7 for an unusable one (about 1 in 200 such starts under load). */
static void version_text(void *handle, const char *(*get_version)(void), char *text, size_t size)
{
    const unsigned long *hex = (const unsigned long *)dlsym(handle, "Py_Version");
    if (hex) {
        snprintf(text, size, "%lu.%lu.%lu", (*hex >> 24) & 0xffUL, (*hex >> 16) & 0xffUL, (*hex >> 8) & 0xffUL);
        return;
    }
    const char *v = get_version();
    snprintf(text, size, "%.*s", (int)strcspn(v, " "), v);
}

static int version_ok(const char *version, int *minor)
{
    int major = 0;
    *minor = 0;
    if (sscanf(version, "%d.%d", &major, minor) != 2) return 0;
    return major == 3 && *minor >= 10;
}

static int file_exists(const char *path)
{
    return access(path, F_OK) == 0;
}

/* The prefix of the Python whose library is `lib`: the nearest ancestor folder holding
 * lib/python3.X/encodings (its standard library), e.g. /usr for
 * /usr/lib/x86_64-linux-gnu/libpython3.11.so.1.0. */
static int find_home(const char *lib, int minor, char *home, size_t size)
{
    char dir[PATH_MAX], probe[PATH_MAX + 64];
    if (!realpath(lib, dir)) snprintf(dir, sizeof dir, "%s", lib);
    for (char *slash = strrchr(dir, '/'); slash; slash = strrchr(dir, '/')) {
        *slash = '\0';
        snprintf(probe, sizeof probe, "%s/lib/python3.%d/encodings/__init__.py", dir, minor);
        if (file_exists(probe)) {
            snprintf(home, size, "%s", dir[0] ? dir : "/");
            return 1;
        }
    }
    return 0;
}

/* Start an isolated interpreter: no site-packages, no user site, environment ignored, standard
 * library of the loaded libpython only.  Py_InitializeEx aborts the process on failure, so the
 * standard library is checked first. */
static int start_interpreter(void *handle, int minor)
{
    static wchar_t *whome = NULL, *wname = NULL;
    Dl_info info;
    char home[PATH_MAX];
    if (!dladdr(*(void **)&py.Py_GetVersion, &info) || !info.dli_fname) {
        report("  cannot tell the file of the loaded libpython\n");
        return 0;
    }
    if (!find_home(info.dli_fname, minor, home, sizeof home)) {
        report("  %s: no standard library (lib/python3.%d/encodings) above it\n", info.dli_fname, minor);
        return 0;
    }
#define CHECK_FLAG(name) if (!py.name) { report("  %s: no %s (interpreter configuration)\n", info.dli_fname, #name); return 0; }
    PY_FLAGS(CHECK_FLAG)
#undef CHECK_FLAG
    *py.Py_IsolatedFlag = 1;
    *py.Py_NoSiteFlag = 1;
    *py.Py_IgnoreEnvironmentFlag = 1;
    *py.Py_NoUserSiteDirectory = 1;
    *py.Py_DontWriteBytecodeFlag = 1;
    *py.Py_UTF8Mode = 1; /* file names in any locale (LANG=C too): UTF-8, undecodable bytes kept as they are */
    whome = py.Py_DecodeLocale(home, NULL);
    wname = py.Py_DecodeLocale("pogofmu", NULL);
    if (!whome || !wname) return 0;
    py.Py_SetPythonHome(whome);
    py.Py_SetProgramName(wname);
    py.Py_InitializeEx(0); /* no signal handlers: the host keeps its own */
    if (!py.Py_IsInitialized()) return 0;
    py.PyEval_SaveThread(); /* release the GIL; every call takes it with PyGILState_Ensure */
    (void)handle;
    return 1;
}

static int try_library(const char *path)
{
    const char *missing = NULL;
    int minor;
    void *handle = dlopen(path, RTLD_NOW | RTLD_GLOBAL);
    if (!handle) {
        report("  %s: %s\n", path, dlerror());
        return 0;
    }
    if (!resolve(handle, &missing)) {
        report("  %s: lacks %s\n", path, missing);
        return 0; /* left loaded: dlclose of a libpython is not safe */
    }
    char version[64];
    int fd = lock_interpreter_start(*(void **)&py.Py_GetVersion);
    version_text(handle, py.Py_GetVersion, version, sizeof version);
    if (!version_ok(version, &minor)) {
        unlock_interpreter_start(fd);
        report("  %s: CPython %s, need >= 3.10\n", path, version);
        return 0;
    }
    int ok = py.Py_IsInitialized() /* already running in this process (another FMU) */ ||
             start_interpreter(handle, minor);
    unlock_interpreter_start(fd);
    if (ok) return 1;
    report("  %s: could not start an interpreter\n", path);
    return 0;
}

/* Candidate libraries from the launch file (python=... lines) */
static int try_launch_file(const char *resources)
{
    char path[PATH_MAX + 32], line[PATH_MAX + 32];
    snprintf(path, sizeof path, "%s/pogofmu_launch.txt", resources);
    FILE *f = fopen(path, "r");
    if (!f) return 0;
    int ok = 0;
    while (!ok && fgets(line, sizeof line, f)) {
        line[strcspn(line, "\r\n")] = '\0';
        if (strncmp(line, "python=", 7) == 0 && line[7]) ok = try_library(line + 7);
    }
    fclose(f);
    return ok;
}

/* For each python3 on PATH: .../bin/python3 -> python3.X -> .../lib/libpython3.X.so.1.0 */
static int try_path_pythons(void)
{
    const char *path = getenv("PATH");
    if (!path) return 0;
    char *copy = strdup(path), *save = NULL;
    int ok = 0;
    for (char *dir = strtok_r(copy, ":", &save); dir && !ok; dir = strtok_r(NULL, ":", &save)) {
        char exe[PATH_MAX + 16], real[PATH_MAX], lib[PATH_MAX + 64];
        snprintf(exe, sizeof exe, "%s/python3", dir);
        if (!realpath(exe, real)) continue;
        const char *base = strrchr(real, '/');
        int minor;
        if (!base || sscanf(base + 1, "python3.%d", &minor) != 1 || minor < 10) continue;
        *strrchr(real, '/') = '\0';
        char *bin = strrchr(real, '/');
        if (!bin) continue;
        *bin = '\0';
        snprintf(lib, sizeof lib, "%s/lib/libpython3.%d.so.1.0", real, minor);
        if (file_exists(lib)) ok = try_library(lib);
        if (!ok) { /* multiarch layouts (/usr/lib/x86_64-linux-gnu): by soname */
            snprintf(lib, sizeof lib, "libpython3.%d.so.1.0", minor);
            ok = try_library(lib);
        }
    }
    free(copy);
    return ok;
}

static int try_usual_places(void)
{
    static const char *dirs[] = {"", "/usr/local/lib/", "/usr/lib/", "/usr/lib64/",
                                 "/usr/lib/x86_64-linux-gnu/", "/usr/lib/aarch64-linux-gnu/"};
    char lib[256];
    for (int minor = 13; minor >= 10; --minor)
        for (size_t d = 0; d < sizeof dirs / sizeof *dirs; ++d) {
            snprintf(lib, sizeof lib, "%slibpython3.%d.so.1.0", dirs[d], minor);
            if ((d == 0 || file_exists(lib)) && try_library(lib)) return 1;
        }
    return 0;
}

/* Compile resources/pogofmu_boot.py once per process (per copy of this library). */
static int load_boot(const char *resources)
{
    char path[PATH_MAX + 32];
    snprintf(path, sizeof path, "%s/pogofmu_boot.py", resources);
    FILE *f = fopen(path, "rb");
    if (!f) {
        report("  cannot read %s: %s\n", path, strerror(errno));
        return 0;
    }
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *src = malloc((size_t)n + 1);
    size_t got = src ? fread(src, 1, (size_t)n, f) : 0;
    fclose(f);
    if (!src || got != (size_t)n) {
        free(src);
        return 0;
    }
    src[n] = '\0';
    int ok = 0;
    GIL g = py.PyGILState_Ensure();
    PyObject *code = py.Py_CompileString(src, path, Py_file_input);
    PyObject *globals = py.PyDict_New();
    PyObject *builtins = py.PyImport_ImportModule("builtins");
    if (code && globals && builtins && py.PyDict_SetItemString(globals, "__builtins__", builtins) == 0) {
        PyObject *r = py.PyEval_EvalCode(code, globals, globals);
        if (r) {
            py.Py_DecRef(r);
            boot = globals;
            globals = NULL;
            ok = 1;
        }
    }
    if (!ok) {
        PyObject *t = NULL, *v = NULL, *tb = NULL, *s = NULL;
        py.PyErr_Fetch(&t, &v, &tb);
        s = v ? py.PyObject_Str(v) : NULL;
        PyObject *b = s ? py.PyUnicode_AsUTF8String(s) : NULL;
        report("  %s: %s\n", path, b ? py.PyBytes_AsString(b) : "cannot be run");
        if (b) py.Py_DecRef(b);
        if (s) py.Py_DecRef(s);
        if (t) py.Py_DecRef(t);
        if (v) py.Py_DecRef(v);
        if (tb) py.Py_DecRef(tb);
    }
    if (code) py.Py_DecRef(code);
    if (globals) py.Py_DecRef(globals);
    if (builtins) py.Py_DecRef(builtins);
    py.PyGILState_Release(g);
    free(src);
    return ok;
}

/* Make sure an interpreter runs and the boot code is loaded: 1; 0 no usable interpreter, -1 the
 * boot code cannot be read or run, -2 the host's own CPython (its version in python_report) is too
 * old; python_report says what was tried or what failed. */
int ensure_python(const char *resources)
{
    pthread_mutex_lock(&boot_lock);
    if (!python_ready) {
        const char *missing = NULL;
        const char *env = getenv("POGOFMU_PYTHON_LIB");
        python_report[0] = '\0';
        const char *(*host_version)(void) = NULL;
        int (*host_running)(void) = NULL;
        *(void **)&host_version = dlsym(RTLD_DEFAULT, "Py_GetVersion");
        *(void **)&host_running = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
        int minor;
        char version[64];
        if (host_version && host_running && host_running()) {
            int fd = lock_interpreter_start(*(void **)&host_version);
            version_text(RTLD_DEFAULT, host_version, version, sizeof version);
            unlock_interpreter_start(fd);
            if (!version_ok(version, &minor)) {
                /* the host runs a CPython of its own (one per process): the FMU's code would run in
                 * it, and no other libpython can be started beside it */
                snprintf(python_report, sizeof python_report, "%s", version);
                pthread_mutex_unlock(&boot_lock);
                return -2;
            }
        }
        if (dlsym(RTLD_DEFAULT, "Py_IsInitialized") && resolve(RTLD_DEFAULT, &missing)) {
            int fd = lock_interpreter_start(*(void **)&py.Py_GetVersion);
            version_text(RTLD_DEFAULT, py.Py_GetVersion, version, sizeof version);
            if (!version_ok(version, &minor)) {
                report("  the CPython linked into this process is %s, need >= 3.10\n", version);
            } else if (py.Py_IsInitialized()) {
                python_ready = 1;
            } else {
                python_ready = start_interpreter(RTLD_DEFAULT, minor);
                if (!python_ready) report("  the CPython linked into this process could not be started\n");
            }
            unlock_interpreter_start(fd);
        } else {
            /* an explicit choice is authoritative: that library or a clear error */
            python_ready = (env && *env) ? try_library(env)
                                         : try_launch_file(resources) || try_path_pythons() || try_usual_places();
        }
    }
    if (python_ready && !boot) python_report[0] = '\0'; /* (only the boot code's reason from here) */
    int ok = !python_ready ? 0 : (boot || load_boot(resources)) ? 1 : -1;
    pthread_mutex_unlock(&boot_lock);
    return ok;
}

