/* The bridge to Python: the backend (pg_backend.h) of the Python-hosted FMUs' binaries.
 *
 * Linked with the FMI entry file of its FMI version (fmi2/pg_fmi2.c or fmi3/pg_fmi3.c, the same
 * files the native FMUs are built from) and the embedding of CPython (python_embed.c), it carries
 * each call to the FMU's Python code (the slave object of resources/<module>.py, standard library
 * only). What it does that Python alone cannot:
 *
 *   - brings its interpreter (python_embed.c): it uses the CPython already in the process (fmpy,
 *     libcosimpy, a notebook) or, in a host without one (a C importer), loads a libpython >= 3.10
 *     itself and starts an interpreter isolated from the host's environment and site-packages;
 *     if none works, instantiation logs what it tried and fails; it never aborts the host;
 *   - serves outputs from buffers the Python side fills once per step (no Python call per
 *     fmi2GetReal / fmi3GetFloat64 after a step);
 *   - maps Python exceptions to FMI statuses (an exception carrying ``fmi_status`` gives that
 *     status, any other is Fatal) and logs their message; after Fatal the instance refuses every
 *     call but FreeInstance (and Reset, which starts it over);
 *   - FMI 3.0: passes eventModeUsed / earlyReturnAllowed to Python and returns the event flags
 *     of fmi3DoStep, fmi3UpdateDiscreteStates and fmi3CompletedIntegratorStep.
 *
 * It needs no FMI header: statuses are PG_ST_* (the numbers of fmi2Status and fmi3Status). */
#define _GNU_SOURCE
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <dlfcn.h>

#include "pg_backend.h"
#include "python_embed.h" /* CPython, resolved at run time */

typedef int Status;
#define ST_OK PG_ST_OK
#define ST_WARNING PG_ST_WARNING
#define ST_DISCARD PG_ST_DISCARD
#define ST_ERROR PG_ST_ERROR
#define ST_FATAL PG_ST_FATAL
typedef unsigned VR;

struct PgBackend {
    char *name;
    PgLogFn log;       /* the entry file's (it filters) */
    void *log_env;
    int fmi;
    int dead;          /* after a fatal error: refuse everything but free (and reset) */
    PyObject *obj;     /* the Python slave */
    PyObject *queue;   /* its log queue (a list) */
    PyObject *buffers; /* tuple (real vrs, int vrs, output array, control array) */
    PyObject *step_fn; /* the slave's bound step method (looked up at the first step) */
    double *real_out;
    int *int_out;
    int *control;      /* control[0]: outputs in the buffers are current */
    int *real_slot, *int_slot; /* value reference -> buffer slot, -1 if not buffered */
    size_t n_slots;
    size_t nx, nz;     /* FMI 3.0: continuous states, event indicators */
    unsigned *arrays;  /* FMI 3.0: the slave's array_table(), n_arrays (vr, elements) pairs */
    size_t n_arrays;
    char **known;      /* the FMU's log categories */
    size_t n_known;
};
typedef struct PgBackend Inst;

static void emit(Inst *in, int status, const char *category, const char *message)
{
    if (in->log) in->log(in->log_env, status, category, message);
}

#define STATE_MAGIC 0x706f676fu /* 'pogo': a state handle of this bridge (any build, either FMI version) */

typedef struct {
    unsigned magic;
    unsigned mode; /* the instance's call state when the state was taken (serialized with it) */
    PyObject *state;
    PyObject *bytes; /* serialized form, kept between SerializedFMUStateSize and Serialize */
} StateHandle;

typedef struct {
    int status;
    char *category;
    char *message;
} Message;

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

/* Take the queued log messages out of Python (GIL held). */
static Message *drain(Inst *in, size_t *count, int *worst)
{
    *count = 0;
    if (!in->queue) return NULL;
    Py_ssize_t_ n = py.PySequence_Size(in->queue);
    if (n <= 0) {
        if (n < 0) py.PyErr_Clear();
        return NULL;
    }
    Message *msgs = calloc((size_t)n, sizeof *msgs);
    for (Py_ssize_t_ i = 0; msgs && i < n; ++i) {
        PyObject *item = py.PySequence_GetItem(in->queue, i); /* (status, category, msg, ...) */
        PyObject *st = item ? py.PySequence_GetItem(item, 0) : NULL;
        PyObject *cat = item ? py.PySequence_GetItem(item, 1) : NULL;
        PyObject *msg = item ? py.PySequence_GetItem(item, 2) : NULL;
        msgs[i].status = st ? (int)py.PyLong_AsLong(st) : ST_OK;
        msgs[i].category = utf8_of(cat);
        msgs[i].message = utf8_of(msg);
        if (msgs[i].status > *worst) *worst = msgs[i].status;
        if (st) py.Py_DecRef(st);
        if (cat) py.Py_DecRef(cat);
        if (msg) py.Py_DecRef(msg);
        if (item) py.Py_DecRef(item);
        py.PyErr_Clear();
    }
    py.PyList_SetSlice(in->queue, 0, n, NULL);
    py.PyErr_Clear();
    *count = msgs ? (size_t)n : 0;
    return msgs;
}

/* Hand the drained messages to the entry file (GIL released). */
static void flush(Inst *in, Message *msgs, size_t count)
{
    for (size_t i = 0; i < count; ++i) {
        emit(in, msgs[i].status, msgs[i].category, msgs[i].message); /* the entry file filters */
        free(msgs[i].category);
        free(msgs[i].message);
    }
    free(msgs);
}

static PyObject *build(const char *fmt, ...) /* Py_BuildValue through the va_list entry point */
{
    va_list ap;
    va_start(ap, fmt);
    PyObject *r = py.Py_VaBuildValue(fmt, ap);
    va_end(ap);
    return r;
}

/* The pending Python exception as (status, message); clears it.  GIL held. */
static Status take_exception(char **message)
{
    PyObject *t = NULL, *v = NULL, *tb = NULL;
    py.PyErr_Fetch(&t, &v, &tb);
    py.PyErr_NormalizeException(&t, &v, &tb);
    if (v && tb) py.PyException_SetTraceback(v, tb);
    PyObject *fs = v ? py.PyObject_GetAttrString(v, "fmi_status") : NULL;
    long st = (fs && fs != py.none) ? py.PyLong_AsLong(fs) : ST_FATAL;
    py.PyErr_Clear();
    if (st < ST_WARNING || st > ST_FATAL) st = ST_FATAL;
    PyObject *describe = boot ? py.PyDict_GetItemString(boot, "describe") : NULL; /* borrowed */
    PyObject *args = (describe && v) ? build("(O)", v) : NULL;
    PyObject *text = args ? py.PyObject_CallObject(describe, args) : NULL;
    *message = text ? utf8_of(text) : utf8_of(v);
    py.PyErr_Clear();
    PyObject *refs[] = {text, args, fs, t, v, tb};
    for (size_t i = 0; i < sizeof refs / sizeof *refs; ++i)
        if (refs[i]) py.Py_DecRef(refs[i]);
    return (Status)st;
}

static const char *status_category(int status)
{
    switch (status) {
    case ST_WARNING: return "logStatusWarning";
    case ST_DISCARD: return "logStatusDiscard";
    case ST_ERROR: return "logStatusError";
    case ST_FATAL: return "logStatusFatal";
    default: return "logAll";
    }
}

/* A call into Python: take the GIL, call obj.method(*args), let `use` read the result (GIL
 * still held; it returns a status), map an exception to its status and message, drain the log,
 * release the GIL, hand the messages to the host.  A warning logged during the call makes an OK
 * call return Warning. */
typedef int (*UseResult)(Inst *in, PyObject *result, void *ctx);

static int refused_when_dead(Inst *in)
{
    if (in->dead)
        emit(in, ST_ERROR, "logStatusError",
             "the instance ended with a fatal error: only the free-instance function may be called");
    return in->dead;
}

static Status finish_call(Inst *in, GIL g, PyObject *r, UseResult use, void *ctx);

/* obj.method(*args), args built from `fmt` */
static Status vcall(Inst *in, PyObject *target, const char *method, UseResult use, void *ctx,
                    const char *fmt, va_list ap)
{
    if (refused_when_dead(in)) return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    PyObject *args = fmt ? py.Py_VaBuildValue(fmt, ap) : py.PyTuple_New(0);
    PyObject *fn = py.PyObject_GetAttrString(target ? target : in->obj, method);
    PyObject *r = (fn && args) ? py.PyObject_CallObject(fn, args) : NULL;
    if (fn) py.Py_DecRef(fn);
    if (args) py.Py_DecRef(args);
    return finish_call(in, g, r, use, ctx);
}

/* The step, the call made most often: the slave's bound method looked up once per instance and
 * its two floats passed without a format string; otherwise as vcall. */
static Status step_call(Inst *in, const char *method, UseResult use, void *ctx, double t, double h)
{
    if (refused_when_dead(in)) return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    if (!in->step_fn) in->step_fn = py.PyObject_GetAttrString(in->obj, method);
    PyObject *a = py.PyFloat_FromDouble(t), *b = py.PyFloat_FromDouble(h);
    PyObject *r = (in->step_fn && a && b) ? py.PyObject_CallFunctionObjArgs(in->step_fn, a, b, NULL) : NULL;
    if (a) py.Py_DecRef(a);
    if (b) py.Py_DecRef(b);
    return finish_call(in, g, r, use, ctx);
}

/* After the call (GIL held): read the result, map an exception, drain the log, release the GIL,
 * hand the messages to the host. */
static Status finish_call(Inst *in, GIL g, PyObject *r, UseResult use, void *ctx)
{
    Status status = ST_OK;
    char *error = NULL;
    if (r && use) status = (Status)use(in, r, ctx);
    if (r) py.Py_DecRef(r);
    if (py.PyErr_Occurred()) status = take_exception(&error);
    size_t count = 0;
    int worst = ST_OK;
    Message *msgs = drain(in, &count, &worst);
    py.PyGILState_Release(g);
    flush(in, msgs, count);
    if (error) {
        emit(in, status, status_category(status), error);
        free(error);
    }
    if (status == ST_OK && worst == ST_WARNING) status = ST_WARNING;
    if (status == ST_FATAL) in->dead = 1;
    return status;
}

static Status call(Inst *in, const char *method, UseResult use, void *ctx, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    Status st = vcall(in, NULL, method, use, ctx, fmt, ap);
    va_end(ap);
    return st;
}

/* ---- results read while the GIL is held ------------------------------------------------- */

typedef struct {
    int kind; /* 'd' double, 'i' int */
    size_t n;
    void *out;
} Values;

static int read_values(Inst *in, PyObject *seq, void *ctx)
{
    Values *v = ctx;
    Py_ssize_t_ n = py.PySequence_Size(seq);
    if (n != (Py_ssize_t_)v->n) {
        py.PyErr_Clear();
        emit(in, ST_ERROR, "logStatusError", "internal error: the Python side returned the wrong number of values");
        return ST_ERROR;
    }
    for (Py_ssize_t_ i = 0; i < n; ++i) {
        PyObject *item = py.PySequence_GetItem(seq, i);
        if (!item) return ST_ERROR;
        if (v->kind == 'd') ((double *)v->out)[i] = py.PyFloat_AsDouble(item);
        else ((int *)v->out)[i] = (int)py.PyLong_AsLong(item);
        py.Py_DecRef(item);
        if (py.PyErr_Occurred()) return ST_ERROR; /* reported by finish_call */
    }
    return ST_OK;
}

static int read_double(Inst *in, PyObject *r, void *ctx)
{
    (void)in;
    *(double *)ctx = py.PyFloat_AsDouble(r);
    return ST_OK;
}

static int read_bool(Inst *in, PyObject *r, void *ctx)
{
    (void)in;
    *(int *)ctx = py.PyObject_IsTrue(r) > 0;
    return ST_OK;
}

/* FMI 2.0 do_step's result: True (OK) or False (Discard, the pythonfmu convention) */
static int step_result(Inst *in, PyObject *r, void *ctx)
{
    (void)in;
    (void)ctx;
    return py.PyObject_IsTrue(r) > 0 ? ST_OK : ST_DISCARD;
}

/* A tuple of flags (and a trailing double) returned by the Python side: fmi3DoStep,
 * fmi3UpdateDiscreteStates, fmi3CompletedIntegratorStep.  NULL pointers are skipped. */
typedef struct {
    int nb;
    int *b[5];
    double *d;
} Flags;

static int read_flags(Inst *in, PyObject *r, void *ctx)
{
    Flags *f = ctx;
    Py_ssize_t_ want = f->nb + (f->d ? 1 : 0);
    if (py.PySequence_Size(r) != want) {
        py.PyErr_Clear();
        emit(in, ST_ERROR, "logStatusError", "internal error: the Python side returned the wrong number of flags");
        return ST_ERROR;
    }
    for (int i = 0; i < want; ++i) {
        PyObject *item = py.PySequence_GetItem(r, i);
        if (!item) return ST_ERROR;
        if (i < f->nb) {
            if (f->b[i]) *f->b[i] = py.PyObject_IsTrue(item) > 0;
        } else if (f->d) {
            *f->d = py.PyFloat_AsDouble(item);
        }
        py.Py_DecRef(item);
        if (py.PyErr_Occurred()) return ST_ERROR;
    }
    return ST_OK;
}

/* ---- Python lists from C arrays (new references) ---------------------------------------- */

static PyObject *vr_list(const VR vr[], size_t n)
{
    PyObject *l = py.PyList_New((Py_ssize_t_)n);
    for (size_t i = 0; l && i < n; ++i) py.PyList_SetItem(l, (Py_ssize_t_)i, py.PyLong_FromUnsignedLong(vr[i]));
    return l;
}

static PyObject *value_list(char kind, const void *values, size_t n)
{
    PyObject *l = py.PyList_New((Py_ssize_t_)n);
    for (size_t i = 0; l && i < n; ++i) {
        PyObject *o = kind == 'd' ? py.PyFloat_FromDouble(((const double *)values)[i])
                                  : py.PyLong_FromLong(((const int *)values)[i]);
        py.PyList_SetItem(l, (Py_ssize_t_)i, o);
    }
    return l;
}

static Status get_values(Inst *in, const char *method, char kind, const VR vr[], size_t n, void *out)
{
    if (n == 0) return ST_OK;
    if (refused_when_dead(in)) return ST_ERROR;
    Values v = {kind, n, out};
    GIL g = py.PyGILState_Ensure();
    PyObject *vrs = vr_list(vr, n);
    py.PyGILState_Release(g);
    return call(in, method, read_values, &v, "(N)", vrs);
}

static Status set_values(Inst *in, const char *method, char kind, const VR vr[], size_t n, const void *values)
{
    if (n == 0) return ST_OK;
    if (refused_when_dead(in)) return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    PyObject *vrs = vr_list(vr, n), *vals = value_list(kind, values, n);
    py.PyGILState_Release(g);
    return call(in, method, NULL, NULL, "(NN)", vrs, vals);
}

static Status get_array(Inst *in, const char *method, double out[], size_t n)
{
    Values v = {'d', n, out};
    return call(in, method, read_values, &v, NULL);
}

/* Outputs served from the buffers the Python side fills after each step (no Python call). */
static int from_buffer(Inst *in, const VR vr[], size_t n, char kind, void *out)
{
    if (!in->control || !in->control[0] || in->dead) return 0;
    const int *slot = kind == 'd' ? in->real_slot : in->int_slot;
    for (size_t i = 0; i < n; ++i) {
        if (vr[i] >= in->n_slots || slot[vr[i]] < 0) return 0;
        if (kind == 'd') ((double *)out)[i] = in->real_out[slot[vr[i]]];
        else ((int *)out)[i] = in->int_out[slot[vr[i]]];
    }
    return 1;
}

/* ---- instantiation ----------------------------------------------------------------------- */

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

static char *resources_path(Inst *in, const char *location)
{
    if (!location || !*location) {
        emit(in, ST_ERROR, "logStatusError", in->fmi == 3 ? "resourcePath = NULL: the FMU's Python code lives in resources/"
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
        const char *arg = in->fmi == 3 ? "resourcePath" : "fmuResourceLocation";
        int len = snprintf(msg, size, "cannot read %s/pogofmu_launch.txt%s", tried[0],
                           n == 2 ? " (the location read as a percent-encoded URI)" : "");
        if (n == 2) len += snprintf(msg + len, size - (size_t)len, " nor %s/pogofmu_launch.txt (read as given)", tried[1]);
        snprintf(msg + len, size - (size_t)len, ": %s = '%s' is not this FMU's resources folder (%s)", arg, location,
                 in->fmi == 3 ? "FMI 3.0: the path of the extracted FMU's resources/ folder"
                              : "FMI 2.0: the extracted FMU's resources/ folder as a file URI, e.g. file:///path/resources");
        emit(in, ST_ERROR, "logStatusError", msg);
    }
    free(msg);
    free(tried[0]);
    free(tried[1]);
    return NULL;
}

/* The instantiation token recorded at build time must match the one the importer read from the
 * modelDescription (FMI: an FMU refuses a foreign description). */
static int token_matches(Inst *in, const char *resources, const char *token)
{
    char path[PATH_MAX + 32], line[512];
    snprintf(path, sizeof path, "%s/pogofmu_launch.txt", resources);
    FILE *f = fopen(path, "r");
    if (!f) {
        char msg[PATH_MAX + 128];
        snprintf(msg, sizeof msg, "cannot read %s: is the resource location right?", path);
        emit(in, ST_ERROR, "logStatusError", msg);
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
        emit(in, ST_ERROR, "logStatusError", msg);
        return 0;
    }
    if (!ok) {
        char msg[1024];
        snprintf(msg, sizeof msg, "instantiation token %s does not match this FMU's (%s): the model "
                 "description read by the importer belongs to another FMU or build", token ? token : "(null)",
                 found ? "see resources/pogofmu_launch.txt" : "none recorded");
        emit(in, ST_ERROR, "logStatusError", msg);
    }
    return ok;
}

static int map_buffer(PyObject *array, void **address)
{
    PyObject *fn = py.PyObject_GetAttrString(array, "buffer_info");
    PyObject *info = fn ? py.PyObject_CallObject(fn, NULL) : NULL;
    PyObject *addr = info ? py.PySequence_GetItem(info, 0) : NULL;
    *address = addr ? py.PyLong_AsVoidPtr(addr) : NULL;
    PyObject *refs[] = {addr, info, fn};
    for (size_t i = 0; i < 3; ++i)
        if (refs[i]) py.Py_DecRef(refs[i]);
    return *address != NULL;
}

/* Slot table for one buffer: table[vr] = position of vr in `vrs` (a sequence of ints). */
static int fill_slots(PyObject *vrs, int *table, size_t n_slots)
{
    Py_ssize_t_ n = py.PySequence_Size(vrs);
    if (n < 0) return 0;
    for (Py_ssize_t_ i = 0; i < n; ++i) {
        PyObject *o = py.PySequence_GetItem(vrs, i);
        long vr = o ? py.PyLong_AsLong(o) : -1;
        if (o) py.Py_DecRef(o);
        if (vr < 0 || (size_t)vr >= n_slots) return 0;
        table[vr] = (int)i;
    }
    return 1;
}

/* Ask the Python side for its output buffer: (real vrs, int vrs, array('d') holding the reals
 * as doubles followed by the integers as int32 -- one struct call fills it --, array('i')
 * control).  GIL held.  Without it every getter goes through Python. */
static void attach_buffers(Inst *in, PyObject *buffers)
{
    if (!buffers || buffers == py.none || py.PySequence_Size(buffers) != 4) {
        py.PyErr_Clear();
        return;
    }
    PyObject *item[4];
    for (int i = 0; i < 4; ++i) item[i] = py.PySequence_GetItem(buffers, i);
    void *r = NULL, *c = NULL;
    Py_ssize_t_ n_real = py.PySequence_Size(item[0]);
    size_t max_vr = 0;
    for (int k = 0; k < 2; ++k) {
        Py_ssize_t_ n = py.PySequence_Size(item[k]);
        for (Py_ssize_t_ i = 0; i < n; ++i) {
            PyObject *o = py.PySequence_GetItem(item[k], i);
            long vr = o ? py.PyLong_AsLong(o) : -1;
            if (o) py.Py_DecRef(o);
            if (vr >= 0 && (size_t)vr + 1 > max_vr) max_vr = (size_t)vr + 1;
        }
    }
    if (n_real >= 0 && max_vr && max_vr < 1000000 && map_buffer(item[2], &r) && map_buffer(item[3], &c)) {
        in->n_slots = max_vr;
        in->real_slot = malloc(max_vr * sizeof(int));
        in->int_slot = malloc(max_vr * sizeof(int));
        if (in->real_slot && in->int_slot) {
            for (size_t i = 0; i < max_vr; ++i) in->real_slot[i] = in->int_slot[i] = -1;
            if (fill_slots(item[0], in->real_slot, max_vr) && fill_slots(item[1], in->int_slot, max_vr)) {
                in->real_out = r;
                in->int_out = (int *)((char *)r + (size_t)n_real * sizeof(double));
                in->control = c;
                in->buffers = buffers;
                py.Py_IncRef(buffers);
            }
        }
        if (!in->control) {
            free(in->real_slot);
            free(in->int_slot);
            in->real_slot = in->int_slot = NULL;
            in->n_slots = 0;
        }
    }
    for (int i = 0; i < 4; ++i)
        if (item[i]) py.Py_DecRef(item[i]);
    py.PyErr_Clear();
}

void pgb_free(PgBackend *in)
{
    if (!in) return;
    if (python_ready && (in->obj || in->queue || in->buffers || in->step_fn)) {
        GIL g = py.PyGILState_Ensure();
        PyObject *refs[] = {in->buffers, in->queue, in->step_fn, in->obj};
        for (size_t i = 0; i < sizeof refs / sizeof *refs; ++i)
            if (refs[i]) py.Py_DecRef(refs[i]);
        py.PyErr_Clear();
        py.PyGILState_Release(g);
    }
    for (size_t i = 0; i < in->n_known; ++i) free(in->known[i]);
    free(in->known);
    free(in->arrays);
    free(in->real_slot);
    free(in->int_slot);
    free(in->name);
    free(in);
}

/* What the entry points check without asking Python: the FMU's log categories, and (FMI 3.0)
 * the numbers of continuous states and event indicators. Needs the GIL. */
static void read_interface(Inst *in)
{
    PyObject *cats = NULL;
    PyObject *seq = py.PyObject_GetAttrString(in->obj, "log_category_names"); /* a tuple of str */
    Py_ssize_t_ n = seq ? py.PySequence_Size(seq) : 0;
    if (n > 0 && (in->known = calloc((size_t)n, sizeof(char *)))) {
        for (Py_ssize_t_ i = 0; i < n; ++i) {
            PyObject *item = py.PySequence_GetItem(seq, i);
            char *name = item ? utf8_of(item) : NULL;
            if (item) py.Py_DecRef(item);
            if (name) in->known[in->n_known++] = name;
        }
    }
    if (seq) py.Py_DecRef(seq);
    if (cats) py.Py_DecRef(cats);
    if (in->fmi != 3) {
        py.PyErr_Clear();
        return;
    }
    const char *names[2] = {"number_of_continuous_states", "number_of_event_indicators"};
    size_t *dest[2] = {&in->nx, &in->nz};
    for (int k = 0; k < 2; ++k) {
        PyObject *m = py.PyObject_GetAttrString(in->obj, names[k]);
        PyObject *r = m ? py.PyObject_CallObject(m, NULL) : NULL;
        if (m) py.Py_DecRef(m);
        if (r) {
            *dest[k] = (size_t)py.PyLong_AsLong(r);
            py.Py_DecRef(r);
        }
    }
    PyObject *m = py.PyObject_GetAttrString(in->obj, "array_table"); /* (vr, elements, vr, ...) */
    PyObject *table = m ? py.PyObject_CallObject(m, NULL) : NULL;
    Py_ssize_t_ size = table ? py.PySequence_Size(table) : 0;
    if (size > 0 && (in->arrays = calloc((size_t)size, sizeof *in->arrays))) {
        for (Py_ssize_t_ i = 0; i < size; ++i) {
            PyObject *item = py.PySequence_GetItem(table, i);
            in->arrays[i] = item ? (unsigned)py.PyLong_AsLong(item) : 0u;
            if (item) py.Py_DecRef(item);
        }
        in->n_arrays = (size_t)size / 2;
    }
    if (table) py.Py_DecRef(table);
    if (m) py.Py_DecRef(m);
    py.PyErr_Clear();
}

/* Create the Python slave.  `mode` is passed to _launcher_attach: "cs" or "me"; for FMI 3 CS the
 * event-mode and early-return grants as well.  On failure the reason is logged and NULL returned. */
/* The file of this library: it carries the engine (pg_binding.c), which the FMU's Python code runs
 * through ctypes. */
static const char *own_path(void)
{
    Dl_info info;
    if (dladdr((void *)&own_path, &info) && info.dli_fname) return info.dli_fname;
    return "";
}

static Inst *instantiate(Inst *in, const char *location, const char *token, int visible,
                         const char *mode, int event_mode_used, int early_return_allowed)
{
    char *resources = resources_path(in, location);
    if (!resources) {
        pgb_free(in);
        return NULL;
    }
    if (!token_matches(in, resources, token)) {
        free(resources);
        pgb_free(in);
        return NULL;
    }
    int python = ensure_python(resources);
    if (python <= 0) {
        char *msg = malloc(sizeof python_report + 512);
        if (msg && python == -2) {
            snprintf(msg, sizeof python_report + 512,
                     "this FMU's Python code runs in the CPython of the process that loads it, and this process runs "
                     "CPython %s (the host's own interpreter, e.g. the Python of a ctypes or fmpy importer): the FMU "
                     "needs CPython 3.10 to 3.13. Run the importer under CPython 3.10 or newer (a host without Python "
                     "of its own loads a libpython3.10+ itself), or use the native FMU of this model (dist/native/), "
                     "which needs no Python", python_report);
        } else if (msg && python < 0) {
            snprintf(msg, sizeof python_report + 512,
                     "the FMU's bootstrap resources/pogofmu_boot.py cannot be run (the FMU's resources folder is "
                     "incomplete or unreadable: extract the FMU again):\n%s", python_report);
        } else if (msg) {
            snprintf(msg, sizeof python_report + 512,
                     "no usable CPython (>= 3.10) for this FMU's Python code; set POGOFMU_PYTHON_LIB to "
                     "the path of a libpython3.X.so to choose one. Tried:\n%s",
                     python_report[0] ? python_report : "  (nothing found)\n");
        }
        if (msg) {
            emit(in, ST_ERROR, "logStatusError", msg);
            free(msg);
        }
        free(resources);
        pgb_free(in);
        return NULL;
    }
    GIL g = py.PyGILState_Ensure();
    char *error = NULL;
    PyObject *load = py.PyDict_GetItemString(boot, "load"); /* borrowed */
    /* bytes: the file system's own, in any locale */
    PyObject *args = build("(yy)", resources, own_path());
    PyObject *cls = (load && args) ? py.PyObject_CallObject(load, args) : NULL;
    PyObject *kwargs = cls ? build("{s:s,s:s,s:N,s:s}", "instance_name", in->name, "resources", resources,
                                   "visible", py.PyBool_FromLong(visible), "fmi_binary", "pogofmu") : NULL;
    PyObject *empty = kwargs ? py.PyTuple_New(0) : NULL;
    in->obj = empty ? py.PyObject_Call(cls, empty, kwargs) : NULL;
    PyObject *attach = in->obj ? py.PyObject_GetAttrString(in->obj, "_launcher_attach") : NULL;
    PyObject *aargs = attach ? build("(sNN)", mode, py.PyBool_FromLong(event_mode_used),
                                     py.PyBool_FromLong(early_return_allowed)) : NULL;
    PyObject *buffers = aargs ? py.PyObject_CallObject(attach, aargs) : NULL;
    if (buffers) {
        in->queue = py.PyObject_GetAttrString(in->obj, "log_queue");
        attach_buffers(in, buffers);
        read_interface(in);
    }
    if (py.PyErr_Occurred() || !buffers) {
        if (py.PyErr_Occurred()) take_exception(&error);
        else error = strdup("the FMU's Python code could not be loaded");
    }
    PyObject *refs[] = {buffers, aargs, attach, empty, kwargs, cls, args};
    for (size_t i = 0; i < sizeof refs / sizeof *refs; ++i)
        if (refs[i]) py.Py_DecRef(refs[i]);
    size_t count = 0;
    int worst = ST_OK;
    Message *msgs = (in->queue && !error) ? drain(in, &count, &worst) : NULL;
    py.PyGILState_Release(g);
    flush(in, msgs, count);
    free(resources);
    if (error) {
        emit(in, ST_ERROR, "logStatusError", error);
        free(error);
        pgb_free(in);
        return NULL;
    }
    return in;
}

/* ---- FMU states -------------------------------------------------------------------------- */

static int keep_state(Inst *in, PyObject *r, void *ctx)
{
    (void)in;
    StateHandle *h = ctx;
    py.Py_IncRef(r);
    if (h->state) py.Py_DecRef(h->state);
    if (h->bytes) py.Py_DecRef(h->bytes);
    h->state = r;
    h->bytes = NULL;
    return ST_OK;
}

/* a deserialized state: the state, and the call state the Python side read from the sealed bytes
 * (its "call_state") */
static int keep_restored(Inst *in, PyObject *r, void *ctx)
{
    StateHandle *h = ctx;
    keep_state(in, r, ctx);
    PyObject *mode = py.PyDict_GetItemString(r, "call_state"); /* (borrowed) */
    h->mode = mode ? (unsigned)py.PyLong_AsLong(mode) : 0u;
    py.PyErr_Clear();
    return ST_OK;
}

static int keep_bytes(Inst *in, PyObject *r, void *ctx)
{
    (void)in;
    StateHandle *h = ctx;
    if (h->bytes) py.Py_DecRef(h->bytes);
    py.Py_IncRef(r);
    h->bytes = r;
    return ST_OK;
}

/* The handle behind an FMU state pointer, or NULL (and an Error logged) if it is none of this
 * launcher's: the Python side then checks whose state it is (model, build, FMI version). */
static StateHandle *state_handle(Inst *in, void *state, const char *what)
{
    StateHandle *h = state;
    if (!h || h->magic != STATE_MAGIC || !h->state) {
        char text[200];
        snprintf(text, sizeof text, "%s refused: %s", what,
                 !h ? "no FMU state given (NULL)" : "not an FMU state of a pogofmu FMU (or one already freed)");
        emit(in, ST_ERROR, "logStatusError", text);
        return NULL;
    }
    return h;
}

int pgb_state_get(PgBackend *in, unsigned mode, void **state)
{
    StateHandle *h = *state;
    if (h && h->magic != STATE_MAGIC) {
        emit(in, ST_ERROR, "logStatusError", "get FMU state refused: the state to overwrite is not one of a pogofmu FMU");
        return ST_ERROR;
    }
    if (!h) h = calloc(1, sizeof *h);
    if (!h) return ST_ERROR;
    h->magic = STATE_MAGIC;
    Status st = call(in, "_get_fmu_state", keep_state, h, NULL);
    h->mode = mode;
    if (st <= ST_WARNING) *state = h;
    else if (!*state) free(h);
    return st;
}

int pgb_state_set(PgBackend *in, void *state, unsigned *mode)
{
    StateHandle *h = state_handle(in, state, "set FMU state");
    if (!h) return ST_ERROR;
    Status st = call(in, "_set_fmu_state", NULL, NULL, "(O)", h->state);
    *mode = h->mode; /* the call state it was taken in */
    return st;
}

int pgb_state_mode(PgBackend *in, void *state, unsigned *mode)
{
    StateHandle *h = state_handle(in, state, "set FMU state");
    if (!h) return ST_ERROR;
    *mode = h->mode;
    return ST_OK;
}

int pgb_state_free(PgBackend *in, void **state)
{
    StateHandle *h = state ? *state : NULL;
    if (!h) return ST_OK;
    if (h->magic != STATE_MAGIC) {
        emit(in, ST_ERROR, "logStatusError", "free FMU state refused: not an FMU state of a pogofmu FMU");
        return ST_ERROR;
    }
    GIL g = py.PyGILState_Ensure();
    if (h->state) py.Py_DecRef(h->state);
    if (h->bytes) py.Py_DecRef(h->bytes);
    py.PyGILState_Release(g);
    h->magic = 0;
    free(h);
    *state = NULL;
    return ST_OK;
}

int pgb_state_size(PgBackend *in, void *state, size_t *size)
{
    StateHandle *h = state_handle(in, state, "serialized FMU state size");
    if (!h) return ST_ERROR;
    Status st = call(in, "_fmu_state_to_bytes", keep_bytes, h, "(Ok)", h->state, (unsigned long)h->mode);
    if (st <= ST_WARNING) {
        GIL g = py.PyGILState_Ensure();
        *size = (size_t)py.PyBytes_Size(h->bytes);
        py.PyErr_Clear();
        py.PyGILState_Release(g);
    }
    return st;
}

int pgb_state_serialize(PgBackend *in, void *state, unsigned char *bytes, size_t size)
{
    StateHandle *h = state_handle(in, state, "serialize FMU state");
    size_t n = 0;
    if (!h) return ST_ERROR;
    if (!h->bytes) {
        Status st = pgb_state_size(in, state, &n);
        if (st > ST_WARNING) return st;
    }
    GIL g = py.PyGILState_Ensure();
    n = (size_t)py.PyBytes_Size(h->bytes);
    if (n <= size) memcpy(bytes, py.PyBytes_AsString(h->bytes), n);
    py.PyErr_Clear();
    py.PyGILState_Release(g);
    if (n > size) {
        emit(in, ST_ERROR, "logStatusError", "serialize FMU state: the buffer is smaller than the serialized size");
        return ST_ERROR;
    }
    return ST_OK;
}

int pgb_state_deserialize(PgBackend *in, const unsigned char *bytes, size_t size, void **state)
{
    StateHandle *h = calloc(1, sizeof *h);
    if (!h) return ST_ERROR;
    h->magic = STATE_MAGIC;
    GIL g = py.PyGILState_Ensure();
    PyObject *b = py.PyBytes_FromStringAndSize((const char *)bytes, (Py_ssize_t_)size);
    py.PyGILState_Release(g);
    Status st = call(in, "_fmu_state_from_bytes", keep_restored, h, "(N)", b);
    if (st <= ST_WARNING) *state = h;
    else free(h);
    return st;
}

/* ---- the backend's functions ------------------------------------------------------------- */

PgBackend *pgb_new(const PgSetup *s)
{
    Inst *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->name = strdup(s->instance_name ? s->instance_name : "");
    in->log = s->log, in->log_env = s->log_env, in->fmi = s->fmi;
    if (!in->name) {
        free(in);
        return NULL;
    }
    return instantiate(in, s->resources, s->token, s->visible, s->interface == 'm' ? "me" : "cs",
                       s->event_mode_used, s->early_return_allowed);
}

const char *const *pgb_log_categories(PgBackend *in, size_t *n)
{
    *n = in->n_known;
    return (const char *const *)in->known;
}

const unsigned *pgb_arrays(PgBackend *in, size_t *n)
{
    *n = in->n_arrays;
    return in->arrays;
}

void pgb_counts(PgBackend *in, size_t *nx, size_t *nz)
{
    *nx = in->nx;
    *nz = in->nz;
}

/* start time, stop time and tolerance to the Python side (None where not defined) */
int pgb_setup_experiment(PgBackend *in, int tolerance_defined, double tolerance, double start, int stop_defined,
                         double stop_time)
{
    if (refused_when_dead(in)) return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    PyObject *stop = stop_defined ? py.PyFloat_FromDouble(stop_time) : (py.Py_IncRef(py.none), py.none);
    PyObject *tol = tolerance_defined ? py.PyFloat_FromDouble(tolerance) : (py.Py_IncRef(py.none), py.none);
    py.PyGILState_Release(g);
    return call(in, "setup_experiment", NULL, NULL, "(dNN)", start, stop, tol);
}

int pgb_enter_initialization(PgBackend *in) { return call(in, "enter_initialization_mode", NULL, NULL, NULL); }

int pgb_exit_initialization(PgBackend *in) { return call(in, "exit_initialization_mode", NULL, NULL, NULL); }

int pgb_terminate(PgBackend *in) { return call(in, "terminate", NULL, NULL, NULL); }

int pgb_reset(PgBackend *in)
{
    in->dead = 0; /* a reset instance starts over */
    return call(in, "reset", NULL, NULL, NULL);
}

int pgb_get_real(PgBackend *in, const unsigned vr[], size_t n, double out[])
{
    if (from_buffer(in, vr, n, 'd', out)) return ST_OK;
    return get_values(in, "get_real", 'd', vr, n, out);
}

int pgb_get_integer(PgBackend *in, const unsigned vr[], size_t n, int out[])
{
    if (from_buffer(in, vr, n, 'i', out)) return ST_OK;
    return get_values(in, "get_integer", 'i', vr, n, out);
}

int pgb_set_real(PgBackend *in, const unsigned vr[], size_t n, const double values[])
{
    return set_values(in, "set_real", 'd', vr, n, values);
}

int pgb_set_input_derivatives(PgBackend *in, const unsigned vr[], size_t n, const int order[], const double values[])
{
    if (n == 0) return ST_OK;
    if (refused_when_dead(in)) return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    PyObject *vrs = vr_list(vr, n), *orders = value_list('i', order, n), *vals = value_list('d', values, n);
    py.PyGILState_Release(g);
    return call(in, "set_real_input_derivatives", NULL, NULL, "(NNN)", vrs, orders, vals);
}

int pgb_set_integer(PgBackend *in, const unsigned vr[], size_t n, const int values[])
{
    return set_values(in, "set_integer", 'i', vr, n, values);
}

/* the slave's variable table names the problem (get_boolean / get_string raise for any value
 * reference: there are no such variables) */
int pgb_no_such_type(PgBackend *in, const unsigned vr[], size_t n, const char *type)
{
    if (n == 0) return ST_OK;
    if (refused_when_dead(in)) return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    PyObject *vrs = vr_list(vr, n);
    py.PyGILState_Release(g);
    return call(in, strcmp(type, "Boolean") == 0 ? "get_boolean" : "get_string", NULL, NULL, "(N)", vrs);
}

static Status unsupported(Inst *in, const char *what)
{
    char msg[256];
    snprintf(msg, sizeof msg, "%s is not supported by this FMU", what);
    emit(in, ST_ERROR, "logStatusError", msg);
    return ST_ERROR;
}

int pgb_directional(PgBackend *in, const unsigned *unknowns, size_t n_unknowns, const unsigned *knowns,
                    size_t n_knowns, const double *seed, double *sensitivity, const char *fn)
{
    (void)unknowns, (void)n_unknowns, (void)knowns, (void)n_knowns, (void)seed, (void)sensitivity;
    char what[160];
    snprintf(what, sizeof what, "%s (providesDirectionalDerivative = false)", fn);
    return unsupported(in, what);
}

int pgb_do_step(PgBackend *in, double t, double h) { return step_call(in, "do_step", step_result, NULL, t, h); }

int pgb_last_successful_time(PgBackend *in, double *t)
{
    return call(in, "get_status", read_double, t, "(s)", "last_successful_time");
}

int pgb_terminated(PgBackend *in, int *terminated)
{
    return call(in, "get_status", read_bool, terminated, "(s)", "terminated");
}

int pgb_enter_event_mode(PgBackend *in) { return call(in, "enter_event_mode", NULL, NULL, NULL); }

int pgb_update_discrete_states(PgBackend *in, PgEventFlags *e)
{
    Flags f = {5, {&e->discrete_states_need_update, &e->terminate_simulation, &e->nominals_changed,
                   &e->values_changed, &e->next_event_time_defined}, &e->next_event_time};
    return call(in, "update_discrete_states", read_flags, &f, NULL);
}

int pgb_enter_continuous_time_mode(PgBackend *in) { return call(in, "enter_continuous_time_mode", NULL, NULL, NULL); }

int pgb_completed_integrator_step(PgBackend *in, int *enter_event_mode, int *terminate_simulation)
{
    Flags f = {2, {enter_event_mode, terminate_simulation}, NULL};
    return call(in, "completed_integrator_step", read_flags, &f, NULL);
}

int pgb_set_time(PgBackend *in, double t) { return call(in, "set_time", NULL, NULL, "(d)", t); }

int pgb_set_continuous_states(PgBackend *in, const double *x, size_t n)
{
    if (refused_when_dead(in)) return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    PyObject *list = value_list('d', x, n);
    py.PyGILState_Release(g);
    return call(in, "set_continuous_states", NULL, NULL, "(N)", list);
}

int pgb_get_continuous_states(PgBackend *in, double *x, size_t n) { return get_array(in, "get_continuous_states", x, n); }

int pgb_get_derivatives(PgBackend *in, double *dx, size_t n) { return get_array(in, "get_derivatives", dx, n); }

int pgb_get_event_indicators(PgBackend *in, double *z, size_t n) { return get_array(in, "get_event_indicators", z, n); }

int pgb_get_nominals(PgBackend *in, double *nominals, size_t n) { return get_array(in, "get_nominals", nominals, n); }

int pgb_enter_step_mode(PgBackend *in) { return call(in, "enter_step_mode", NULL, NULL, NULL); }

int pgb_do_step3(PgBackend *in, double t, double h, int *event_handling_needed, int *terminate_simulation,
                 int *early_return, double *last_successful_time)
{
    Flags f = {3, {event_handling_needed, terminate_simulation, early_return}, last_successful_time};
    return step_call(in, "do_step3", read_flags, &f, t, h);
}
