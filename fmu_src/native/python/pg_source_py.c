/* The Python-hosted FMUs' model source (adapter/pg_source.h): the C adapter over a model written in
 * Python.
 *
 * At instantiation it finds the FMU's resources folder, checks the instantiation token, brings its
 * interpreter (python_embed.c: the process's CPython or one it loads) and asks the FMU's boot code
 * (resources/pogofmu_boot.py, hosted()) for the model: a PgFmu built at run time by
 * pogofmu.runtime.hosted (the variable table of runtime/interface.py, as the native FMUs' generated
 * one) whose PgModel's functions are the Python binding's (pogofmu.runtime.solver.cengine.Binding:
 * the hot ones pg_binding.c's trampolines, the cold ones ctypes callbacks). From then on the
 * adapter does all FMI's work in C, as for a native FMU; each call that may reach the model runs
 * with the GIL held, this instance's binding the current one of the thread (pg_binding.c's
 * `current`), and the binding's parameters and settings those of the instance (handed over when
 * their bytes change: set before initialization, or brought back by a state restore). */
#define _GNU_SOURCE
#include <limits.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <dlfcn.h>

#include "pg_source.h"
#include "python_embed.h"

void *pgb_py_enter(void *c); /* engine/pg_binding.c */

struct PgSource {
    PyObject *obj;  /* the HostedFmu (it keeps the PgFmu, the PgModel, the callbacks alive) */
    PyObject *bind; /* its bind(p, s) */
    void *py;       /* the binding's PgbPy */
    int keyed;
    double pkey[PG_MAX_P], skey[PG_NS]; /* the parameters and settings the binding has */
};

static void emit(const PgSetup *s, const char *text)
{
    if (s->log) s->log(s->log_env, PG_ST_ERROR, "logStatusError", text);
}

/* ---- the resources folder -------------------------------------------------------------------
 * FMI 2.0 passes fmuResourceLocation as a URI (file:///a%20b/resources, file:/..., file://localhost/...),
 * FMI 3.0 resourcePath as a path.  Importers differ: several pass "file://" + the path unencoded, so a
 * folder named "50%ab" or "a%20b" is not percent-encoded there.  The candidates, in order: the URI
 * decoded (what the standard says), then the text as given; the first holding the launch file is the
 * FMU's.  '%' counts as an escape only before two hex digits.  malloc'd; trailing '/' removed. */
static int hex_digit(char c) { return (c >= '0' && c <= '9') || ((c | 32) >= 'a' && (c | 32) <= 'f'); }

static char *trimmed_copy(const char *p, int decode)
{
    char *out = malloc(strlen(p) + 1), *q = out;
    if (!out) return NULL;
    for (; *p; ++p) {
        if (decode && p[0] == '%' && hex_digit(p[1]) && hex_digit(p[2])) {
            char hex[3] = {p[1], p[2], '\0'};
            *q++ = (char)strtol(hex, NULL, 16);
            p += 2;
        } else {
            *q++ = *p;
        }
    }
    while (q > out + 1 && q[-1] == '/') --q;
    *q = '\0';
    return out;
}

static int launch_file_readable(const char *resources)
{
    char path[PATH_MAX + 32];
    if (snprintf(path, sizeof path, "%s/pogofmu_launch.txt", resources) >= (int)sizeof path) return 0;
    return access(path, R_OK) == 0;
}

static char *resources_path(const PgSetup *s, const char *location)
{
    if (!location || !*location) {
        emit(s, s->fmi == 3 ? "resourcePath = NULL: the FMU's Python code lives in resources/"
                            : "fmuResourceLocation = NULL: the FMU's Python code lives in resources/");
        return NULL;
    }
    const char *p = location;
    int uri = strncmp(p, "file:", 5) == 0;
    if (strncmp(p, "file://localhost/", 17) == 0) p += 16;
    else if (strncmp(p, "file:///", 8) == 0) p += 7;
    else if (strncmp(p, "file:/", 6) == 0) p += 5;
    char *tried[2] = {trimmed_copy(p, uri), uri ? trimmed_copy(p, 0) : NULL};
    int n = uri && tried[1] && strcmp(tried[0], tried[1]) != 0 ? 2 : 1;
    for (int k = 0; k < n; ++k) {
        if (tried[k] && launch_file_readable(tried[k])) {
            free(tried[1 - k]);
            return tried[k];
        }
    }
    size_t size = 3 * strlen(location) + 600;
    char *msg = malloc(size);
    if (msg && tried[0]) {
        const char *arg = s->fmi == 3 ? "resourcePath" : "fmuResourceLocation";
        int len = snprintf(msg, size, "cannot read %s/pogofmu_launch.txt%s", tried[0],
                           n == 2 ? " (the location read as a percent-encoded URI)" : "");
        if (n == 2) len += snprintf(msg + len, size - (size_t)len, " nor %s/pogofmu_launch.txt (read as given)", tried[1]);
        snprintf(msg + len, size - (size_t)len, ": %s = '%s' is not this FMU's resources folder (%s)", arg, location,
                 s->fmi == 3 ? "FMI 3.0: the path of the extracted FMU's resources/ folder"
                             : "FMI 2.0: the extracted FMU's resources/ folder as a file URI, e.g. file:///path/resources");
        emit(s, msg);
    }
    free(msg);
    free(tried[0]);
    free(tried[1]);
    return NULL;
}

/* The instantiation token recorded at build time must match the one the importer read from the
 * modelDescription (FMI: an FMU refuses a foreign description). */
static int token_matches(const PgSetup *s, const char *resources, const char *token)
{
    char path[PATH_MAX + 32], line[512];
    snprintf(path, sizeof path, "%s/pogofmu_launch.txt", resources);
    FILE *f = fopen(path, "r");
    if (!f) {
        char msg[PATH_MAX + 128];
        snprintf(msg, sizeof msg, "cannot read %s: is the resource location right?", path);
        emit(s, msg);
        return 0;
    }
    int ok = 0, found = 0;
    while (fgets(line, sizeof line, f)) {
        line[strcspn(line, "\r\n")] = '\0';
        if (strncmp(line, "token=", 6) == 0) {
            found = 1;
            ok = token && strcmp(line + 6, token) == 0;
        }
    }
    fclose(f);
    if (!found) {
        char msg[PATH_MAX + 160];
        snprintf(msg, sizeof msg, "%s records no instantiation token: the FMU's resources folder is incomplete "
                 "or damaged (extract the FMU again)", path);
        emit(s, msg);
        return 0;
    }
    if (!ok) {
        char msg[1024];
        snprintf(msg, sizeof msg, "instantiation token %s does not match this FMU's (%s): the model "
                 "description read by the importer belongs to another FMU or build", token ? token : "(null)",
                 found ? "see resources/pogofmu_launch.txt" : "none recorded");
        emit(s, msg);
    }
    return ok;
}

/* The file of this library: it carries the engine (pg_binding.c), which the FMU's Python code runs
 * through ctypes. */
static const char *own_path(void)
{
    Dl_info info;
    if (dladdr((void *)&own_path, &info) && info.dli_fname) return info.dli_fname;
    return "";
}

static PyObject *build(const char *fmt, ...) /* Py_BuildValue through the va_list entry point */
{
    va_list ap;
    va_start(ap, fmt);
    PyObject *r = py.Py_VaBuildValue(fmt, ap);
    va_end(ap);
    return r;
}

static char *utf8_of(PyObject *o) /* new malloc'd copy of str(o), NULL-safe; needs the GIL */
{
    PyObject *s = o ? py.PyObject_Str(o) : NULL;
    PyObject *b = s ? py.PyUnicode_AsUTF8String(s) : NULL;
    char *out = strdup(b ? py.PyBytes_AsString(b) : "(no message)");
    if (b) py.Py_DecRef(b);
    if (s) py.Py_DecRef(s);
    if (!b) py.PyErr_Clear();
    return out;
}

/* the pending Python exception's text (the boot code's describe: an intended error's message, else
 * type, message and where); cleared. GIL held. */
static char *exception_text(void)
{
    PyObject *t = NULL, *v = NULL, *tb = NULL;
    py.PyErr_Fetch(&t, &v, &tb);
    py.PyErr_NormalizeException(&t, &v, &tb);
    if (v && tb) py.PyException_SetTraceback(v, tb);
    PyObject *describe = boot ? py.PyDict_GetItemString(boot, "describe") : NULL; /* borrowed */
    PyObject *args = (describe && v) ? build("(O)", v) : NULL;
    PyObject *text = args ? py.PyObject_CallObject(describe, args) : NULL;
    char *out = text ? utf8_of(text) : utf8_of(v);
    py.PyErr_Clear();
    PyObject *refs[] = {text, args, t, v, tb};
    for (size_t i = 0; i < sizeof refs / sizeof *refs; ++i)
        if (refs[i]) py.Py_DecRef(refs[i]);
    return out;
}

static void *address_of(PyObject *obj, const char *name)
{
    PyObject *a = py.PyObject_GetAttrString(obj, name);
    void *p = a ? py.PyLong_AsVoidPtr(a) : NULL;
    if (a) py.Py_DecRef(a);
    return p;
}

static void python_missing(const PgSetup *s, int python)
{
    char *msg = malloc(sizeof python_report + 512);
    if (!msg) return;
    if (python == -2) {
        snprintf(msg, sizeof python_report + 512,
                 "this FMU's Python code runs in the CPython of the process that loads it, and this process runs "
                 "CPython %s (the host's own interpreter, e.g. the Python of a ctypes or fmpy importer): the FMU "
                 "needs CPython 3.10 to 3.13. Run the importer under CPython 3.10 or newer (a host without Python "
                 "of its own loads a libpython3.10+ itself), or use the native FMU of this model (dist/native/), "
                 "which needs no Python", python_report);
    } else if (python < 0) {
        snprintf(msg, sizeof python_report + 512,
                 "the FMU's bootstrap resources/pogofmu_boot.py cannot be run (the FMU's resources folder is "
                 "incomplete or unreadable: extract the FMU again):\n%s", python_report);
    } else {
        snprintf(msg, sizeof python_report + 512,
                 "no usable CPython (>= 3.10) for this FMU's Python code; set POGOFMU_PYTHON_LIB to "
                 "the path of a libpython3.X.so to choose one. Tried:\n%s",
                 python_report[0] ? python_report : "  (nothing found)\n");
    }
    emit(s, msg);
    free(msg);
}

const PgFmu *pg_source_open(const PgSetup *s, PgSource **out)
{
    *out = NULL;
    char *resources = resources_path(s, s->resources);
    if (!resources) return NULL;
    if (!token_matches(s, resources, s->token)) {
        free(resources);
        return NULL;
    }
    int python = ensure_python(resources);
    if (python <= 0) {
        python_missing(s, python);
        free(resources);
        return NULL;
    }
    PgSource *src = calloc(1, sizeof *src);
    if (!src) {
        free(resources);
        return NULL;
    }
    GIL g = py.PyGILState_Ensure();
    const PgFmu *fmu = NULL;
    PyObject *fn = py.PyDict_GetItemString(boot, "hosted"); /* borrowed */
    /* bytes: the file system's own, in any locale */
    PyObject *args = fn ? build("(yyis)", resources, own_path(), s->fmi, s->instance_name ? s->instance_name : "")
                        : NULL;
    src->obj = args ? py.PyObject_CallObject(fn, args) : NULL;
    if (src->obj) {
        fmu = address_of(src->obj, "fmu_address");
        src->py = address_of(src->obj, "py_address");
        src->bind = py.PyObject_GetAttrString(src->obj, "bind");
    }
    char *error = NULL;
    if (py.PyErr_Occurred()) error = exception_text();
    else if (!fn) error = strdup("the FMU's bootstrap resources/pogofmu_boot.py has no hosted(): another build's");
    if (!error && !(fmu && src->py && src->bind)) error = strdup("the FMU's Python code could not be loaded");
    if (args) py.Py_DecRef(args);
    if (error) {
        if (src->bind) py.Py_DecRef(src->bind);
        if (src->obj) py.Py_DecRef(src->obj);
    }
    py.PyGILState_Release(g);
    free(resources);
    if (error) {
        emit(s, error);
        free(error);
        free(src);
        return NULL;
    }
    *out = src;
    return fmu;
}

void pg_source_close(PgSource *src)
{
    if (!src) return;
    if (python_ready) {
        GIL g = py.PyGILState_Ensure();
        if (src->bind) py.Py_DecRef(src->bind);
        if (src->obj) py.Py_DecRef(src->obj);
        py.PyErr_Clear();
        py.PyGILState_Release(g);
    }
    free(src);
}

int pg_source_enter(PgSource *src, PgInstance *in, PgSourceGuard *g)
{
    g->in = in;
    g->jvp_off = in->st.has_sim && in->st.sim.jvp_off;
    g->gil = py.PyGILState_Ensure();
    g->outer = pgb_py_enter(src->py);
    const PgModel *md = in->fmu->model;
    size_t pb = sizeof(double) * (size_t)md->np, sb = sizeof(double) * (size_t)md->ns;
    if (src->keyed && memcmp(in->st.par, src->pkey, pb) == 0 && memcmp(in->st.set, src->skey, sb) == 0)
        return PG_ST_OK;
    /* the instance's parameters and settings for the binding's Python functions (what they read) */
    PyObject *args = build("(KK)", (unsigned long long)(uintptr_t)in->st.par, (unsigned long long)(uintptr_t)in->st.set);
    PyObject *r = args ? py.PyObject_CallObject(src->bind, args) : NULL;
    if (args) py.Py_DecRef(args);
    if (r) {
        memcpy(src->pkey, in->st.par, pb), memcpy(src->skey, in->st.set, sb);
        src->keyed = 1;
        py.Py_DecRef(r);
        return PG_ST_OK;
    }
    /* not keyed: the next call tries again; this one is refused, never run with other values */
    char *why = exception_text();
    char text[PG_MSG_MAX];
    snprintf(text, sizeof text, "%s: the parameters could not be handed to the model's Python code: %s", md->name,
             why ? why : "(no reason given)");
    free(why);
    if (in->log) in->log(in->log_env, PG_ST_ERROR, "logStatusError", text);
    return PG_ST_ERROR;
}

/* the binding's texts of the Jacobian gone to differences (a flow that does not run on dual
 * numbers), logged as the Python adapter logged them: logSolver */
static void log_switches(PgSource *src, PgInstance *in)
{
    PyObject *fn = py.PyObject_GetAttrString(src->obj, "take_switches");
    PyObject *texts = fn ? py.PyObject_CallObject(fn, NULL) : NULL;
    Py_ssize_t_ n = texts ? py.PySequence_Size(texts) : 0;
    for (Py_ssize_t_ i = 0; i < n; ++i) {
        PyObject *item = py.PySequence_GetItem(texts, i);
        char *text = item ? utf8_of(item) : NULL;
        if (text && in->log) in->log(in->log_env, PG_ST_OK, "logSolver", text);
        free(text);
        if (item) py.Py_DecRef(item);
    }
    if (texts) py.Py_DecRef(texts);
    if (fn) py.Py_DecRef(fn);
    py.PyErr_Clear();
}

void pg_source_leave(PgSource *src, PgSourceGuard *g)
{
    if (!g->jvp_off && g->in->st.has_sim && g->in->st.sim.jvp_off) log_switches(src, g->in);
    pgb_py_enter(g->outer);
    py.PyGILState_Release(g->gil);
}
