/*
 * pogofmu native launcher: the binary of every pogofmu FMU on Linux.
 *
 * It implements the FMI functions in C and forwards each call to the FMU's Python code (the
 * slave object of resources/<module>.py, standard library only).  What it does that Python alone
 * cannot:
 *
 *   - brings its interpreter: it uses the CPython already in the process (fmpy, libcosimpy, a
 *     notebook) or, in a host without one (a C importer), loads a libpython >= 3.10 itself with
 *     RTLD_GLOBAL and starts an interpreter isolated from the host's environment and
 *     site-packages (standard library only).  Search order: $POGOFMU_PYTHON_LIB if set (then
 *     that library only), else the libraries recorded in resources/pogofmu_launch.txt at build
 *     time, the libpython of each python3 on $PATH, then libpython3.13 ... 3.10 by soname and in
 *     the usual folders.  If none
 *     works, the instantiate function logs what it tried and returns NULL; it never aborts the
 *     host.  An interpreter it started is never finalized (nothing runs at the host's exit);
 *   - resolves every CPython function at run time (dlsym), from the stable ABI only: the binary
 *     has no link-time dependency on libpython, and one build serves CPython 3.10 to 3.13;
 *   - serves outputs from buffers the Python side fills once per step (no Python call per
 *     fmi2GetReal / fmi3GetFloat64 after a step);
 *   - maps Python exceptions to FMI statuses (an exception carrying ``fmi_status`` gives that
 *     status, any other is fmiFatal) and logs their message; after fmiFatal the instance
 *     refuses every call but FreeInstance, which stays safe;
 *   - FMI 3: passes eventModeUsed / earlyReturnAllowed to Python and returns the event flags
 *     (eventHandlingNeeded, earlyReturn, lastSuccessfulTime) of fmi3DoStep.
 *
 * Built by build_fmu.py with the system C compiler: -DPOGOFMU_FMI=2 (FMI 2.0 co-simulation) or
 * -DPOGOFMU_FMI=3 (FMI 3.0 model exchange + co-simulation), against the FMI headers fmpy ships.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <unistd.h>
#include <wchar.h>

#if POGOFMU_FMI == 3
#include "fmi3Functions.h"
#else
#include "fmi2Functions.h"
#endif
#include "python_embed.h" /* CPython, resolved at run time: fmu_src/native/python/ */

/* ============================================================================================
 * Instances
 * ========================================================================================== */

#if POGOFMU_FMI == 3
typedef fmi3Status Status;
#define ST_OK fmi3OK
#define ST_WARNING fmi3Warning
#define ST_DISCARD fmi3Discard
#define ST_ERROR fmi3Error
#define ST_FATAL fmi3Fatal
typedef fmi3ValueReference VR;
#else
typedef fmi2Status Status;
#define ST_OK fmi2OK
#define ST_WARNING fmi2Warning
#define ST_DISCARD fmi2Discard
#define ST_ERROR fmi2Error
#define ST_FATAL fmi2Fatal
typedef fmi2ValueReference VR;
#endif

typedef struct {
    char *name;
#if POGOFMU_FMI == 3
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
#else
    fmi2CallbackFunctions cb;
#endif
    int logging_on;
    char **categories; /* enabled categories (NULL: all) */
    size_t n_categories;
    int dead;          /* after a fatal error: refuse everything but FreeInstance */
    PyObject *obj;     /* the Python slave */
    PyObject *queue;   /* its log queue (a list) */
    PyObject *buffers; /* tuple (real vrs, int vrs, output array, control array) */
    PyObject *step_fn; /* the slave's bound step method (looked up at the first step) */
    double *real_out;
    int *int_out;
    int *control;      /* control[0]: outputs in the buffers are current */
    int *real_slot, *int_slot; /* value reference -> buffer slot, -1 if not buffered */
    size_t n_slots;
    PyObject *strings; /* bytes objects behind the last GetString */
    unsigned mode;     /* the call state (call_states.h) */
    int me;            /* FMI 3.0: a model-exchange instance */
    int event_mode_used;
    size_t nx, nz;     /* FMI 3.0: continuous states, event indicators */
    char **known;      /* the FMU's log categories */
    size_t n_known;
} Inst;

#include "call_states.h"

static void emit(Inst *in, int status, const char *category, const char *message);

/* The standard's call states: refuse a call the instance's state does not allow (call_states.h),
 * with Error and a message naming the function, the state and where the standard allows it. */
static int allowed(Inst *in, int rule, const char *function)
{
    const CallRule *r = &CALL_RULES[rule];
    unsigned mask = in->me ? r->me : r->cs;
    char text[700], where[400];
    const int fmi3 = POGOFMU_FMI == 3;
    if (!mask) {
        snprintf(text, sizeof text, "%s refused: it is a %s function, and this instance is a %s instance", function,
                 in->me ? "co-simulation" : "model-exchange", in->me ? "model-exchange" : "co-simulation");
    } else if (!(in->mode & mask)) {
        mode_list(mask, fmi3, where, sizeof where);
        snprintf(text, sizeof text, "%s refused: not allowed in %s (the standard allows it in %s)", function,
                 mode_name(in->mode, fmi3), where);
    } else {
        return 1;
    }
    emit(in, ST_ERROR, "logStatusError", text);
    return 0;
}

#define STATE_MAGIC 0x706f676fu /* 'pogo': a state handle of this launcher (any build, either FMI version) */

typedef struct {
    unsigned magic;
    unsigned mode; /* the instance's call state when the state was taken */
    PyObject *state;
    PyObject *bytes; /* serialized form, kept between SerializedFMUStateSize and Serialize */
} StateHandle;


typedef struct {
    int status;
    char *category;
    char *message;
} Message;

static void emit(Inst *in, int status, const char *category, const char *message)
{
#if POGOFMU_FMI == 3
    if (in->log) in->log(in->env, (fmi3Status)status, category, message);
#else
    if (!in->cb.logger) return;
    /* the FMI 2 logger takes a printf format: double every '%' */
    size_t n = strlen(message), extra = 0;
    for (size_t i = 0; i < n; ++i) extra += message[i] == '%';
    char *text = malloc(n + extra + 1);
    if (!text) return;
    for (size_t i = 0, j = 0; i <= n; ++i) {
        text[j++] = message[i];
        if (message[i] == '%') text[j++] = '%';
    }
    in->cb.logger(in->cb.componentEnvironment, in->name, (fmi2Status)status, category, text);
    free(text);
#endif
}

/* Messages with status OK go out only with logging on and their category enabled; warnings
 * and errors always go out (a user must see why a call failed). */
static int wanted(Inst *in, int status, const char *category)
{
    if (status >= ST_WARNING) return 1;
    if (!in->logging_on) return 0;
    if (!in->categories) return 1;
    for (size_t i = 0; i < in->n_categories; ++i)
        if (strcmp(in->categories[i], category) == 0) return 1;
    return 0;
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

/* Hand the drained messages to the host (GIL released). */
static void flush(Inst *in, Message *msgs, size_t count)
{
    for (size_t i = 0; i < count; ++i) {
        if (wanted(in, msgs[i].status, msgs[i].category))
            emit(in, msgs[i].status, msgs[i].category, msgs[i].message);
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
    int kind; /* 'd' double, 'i' int, 'b' boolean (int or bool), 's' string */
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
    if (v->kind == 's') {
        if (in->strings) py.Py_DecRef(in->strings);
        in->strings = py.PyList_New(n); /* keeps the UTF-8 bytes alive until the next call */
    }
    for (Py_ssize_t_ i = 0; i < n; ++i) {
        PyObject *item = py.PySequence_GetItem(seq, i);
        if (!item) return ST_ERROR;
        switch (v->kind) {
        case 'd': ((double *)v->out)[i] = py.PyFloat_AsDouble(item); break;
        case 'i': ((int *)v->out)[i] = (int)py.PyLong_AsLong(item); break;
#if POGOFMU_FMI == 3
        case 'b': ((fmi3Boolean *)v->out)[i] = py.PyObject_IsTrue(item) > 0; break;
        case 'q': ((long long *)v->out)[i] = py.PyLong_AsLongLong(item); break;
#else
        case 'b': ((int *)v->out)[i] = py.PyObject_IsTrue(item) > 0; break;
#endif
        case 's': {
            PyObject *b = py.PyUnicode_AsUTF8String(item);
            ((const char **)v->out)[i] = b ? py.PyBytes_AsString(b) : "";
            if (b && in->strings) py.PyList_SetItem(in->strings, i, b); /* steals b */
            else if (b) py.Py_DecRef(b);
            break;
        }
        }
        py.Py_DecRef(item);
        if (py.PyErr_Occurred()) return ST_ERROR; /* reported by vcall */
    }
    return ST_OK;
}

#if POGOFMU_FMI == 2 /* FMI 2 status getters and fmi2DoStep */
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

/* do_step's result: True (OK) or False (Discard, the pythonfmu convention) */
static int step_result(Inst *in, PyObject *r, void *ctx)
{
    (void)in;
    (void)ctx;
    return py.PyObject_IsTrue(r) > 0 ? ST_OK : ST_DISCARD;
}
#endif

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
        PyObject *o;
        switch (kind) {
        case 'd': o = py.PyFloat_FromDouble(((const double *)values)[i]); break;
        case 'i': o = py.PyLong_FromLong(((const int *)values)[i]); break;
        case 'q': o = py.PyLong_FromLongLong(((const long long *)values)[i]); break;
#if POGOFMU_FMI == 3
        case 'b': o = py.PyBool_FromLong(((const fmi3Boolean *)values)[i]); break;
#else
        case 'b': o = py.PyBool_FromLong(((const int *)values)[i]); break;
#endif
        default: {
            const char *s = ((const char *const *)values)[i];
            o = py.PyUnicode_FromString(s ? s : "");
        }
        }
        py.PyList_SetItem(l, (Py_ssize_t_)i, o);
    }
    return l;
}

static Status get_values(Inst *in, const char *method, char kind, const VR vr[], size_t n, void *out)
{
    if (n == 0) return ST_OK;
    Values v = {kind, n, out};
    GIL g = py.PyGILState_Ensure();
    PyObject *vrs = vr_list(vr, n);
    py.PyGILState_Release(g);
    return call(in, method, read_values, &v, "(N)", vrs);
}

static Status set_values(Inst *in, const char *method, char kind, const VR vr[], size_t n, const void *values)
{
    if (n == 0) return ST_OK;
    GIL g = py.PyGILState_Ensure();
    PyObject *vrs = vr_list(vr, n), *vals = value_list(kind, values, n);
    py.PyGILState_Release(g);
    return call(in, method, NULL, NULL, "(NN)", vrs, vals);
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

/* resources folder from an FMI 2 URI (file:///a%20b/resources, file:/..., file://localhost/...)
 * or an FMI 3 path; trailing separators removed.  malloc'd. */
static char *resources_path(const char *location)
{
    if (!location) return NULL;
    const char *p = location;
    if (strncmp(p, "file://localhost/", 17) == 0) p += 16;
    else if (strncmp(p, "file:///", 8) == 0) p += 7;
    else if (strncmp(p, "file:/", 6) == 0) p += 5;
    char *out = malloc(strlen(p) + 1), *q = out;
    if (!out) return NULL;
    for (; *p; ++p) {
        unsigned hex;
        if (p[0] == '%' && p[1] && p[2] && sscanf(p + 1, "%2x", &hex) == 1) {
            *q++ = (char)hex;
            p += 2;
        } else {
            *q++ = *p;
        }
    }
    while (q > out + 1 && q[-1] == '/') --q;
    *q = '\0';
    return out;
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

static void free_inst(Inst *in)
{
    if (!in) return;
    if (python_ready && (in->obj || in->queue || in->buffers || in->strings || in->step_fn)) {
        GIL g = py.PyGILState_Ensure();
        PyObject *refs[] = {in->strings, in->buffers, in->queue, in->step_fn, in->obj};
        for (size_t i = 0; i < sizeof refs / sizeof *refs; ++i)
            if (refs[i]) py.Py_DecRef(refs[i]);
        py.PyErr_Clear();
        py.PyGILState_Release(g);
    }
    for (size_t i = 0; i < in->n_categories; ++i) free(in->categories[i]);
    free(in->categories);
    for (size_t i = 0; i < in->n_known; ++i) free(in->known[i]);
    free(in->known);
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
#if POGOFMU_FMI == 3
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
#endif
    py.PyErr_Clear();
}

/* Create the Python slave.  `mode` is passed to _native_attach: "cs" or "me"; for FMI 3 CS the
 * event-mode and early-return grants as well.  On failure the reason is logged and NULL returned. */
static Inst *instantiate(Inst *in, const char *location, const char *token, int visible,
                         const char *mode, int event_mode_used, int early_return_allowed)
{
    char *resources = resources_path(location);
    if (!resources) {
        emit(in, ST_ERROR, "logStatusError", "no resource location given: the FMU's Python code lives in resources/");
        free_inst(in);
        return NULL;
    }
    if (!token_matches(in, resources, token)) {
        free(resources);
        free_inst(in);
        return NULL;
    }
    int python = ensure_python(resources);
    if (python <= 0) {
        char *msg = malloc(sizeof python_report + 512);
        if (msg && python < 0) {
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
        free_inst(in);
        return NULL;
    }
    GIL g = py.PyGILState_Ensure();
    char *error = NULL;
    PyObject *load = py.PyDict_GetItemString(boot, "load"); /* borrowed */
    PyObject *args = build("(y)", resources); /* bytes: the file system's own, in any locale */
    PyObject *cls = (load && args) ? py.PyObject_CallObject(load, args) : NULL;
    PyObject *kwargs = cls ? build("{s:s,s:s,s:N,s:s}", "instance_name", in->name, "resources", resources,
                                   "visible", py.PyBool_FromLong(visible), "fmi_binary", "pogofmu") : NULL;
    PyObject *empty = kwargs ? py.PyTuple_New(0) : NULL;
    in->obj = empty ? py.PyObject_Call(cls, empty, kwargs) : NULL;
    PyObject *attach = in->obj ? py.PyObject_GetAttrString(in->obj, "_native_attach") : NULL;
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
        free_inst(in);
        return NULL;
    }
    in->mode = MODE_INSTANTIATED;
    return in;
}

static Status set_logging(Inst *in, int on, size_t n, const char *const categories[], const char *function)
{
    for (size_t i = 0; i < n; ++i) { /* every category must be one of the FMU's (the modelDescription's) */
        int known = 0;
        for (size_t k = 0; k < in->n_known && !known; ++k) known = categories[i] && strcmp(categories[i], in->known[k]) == 0;
        if (!known && in->n_known) {
            char text[1200];
            size_t used = (size_t)snprintf(text, sizeof text, "%s refused: %s%s%s is not a log category of this FMU "
                                           "(the categories are", function, categories[i] ? "'" : "",
                                           categories[i] ? categories[i] : "NULL", categories[i] ? "'" : "");
            for (size_t k = 0; k < in->n_known && used < sizeof text; ++k)
                used += (size_t)snprintf(text + used, sizeof text - used, "%s%s", k ? ", " : " ", in->known[k]);
            if (used < sizeof text) snprintf(text + used, sizeof text - used, ")");
            emit(in, ST_ERROR, "logStatusError", text);
            return ST_ERROR;
        }
    }
    for (size_t i = 0; i < in->n_categories; ++i) free(in->categories[i]);
    free(in->categories);
    in->categories = NULL;
    in->n_categories = 0;
    in->logging_on = on;
    if (n > 0) {
        in->categories = calloc(n, sizeof(char *));
        if (!in->categories) return ST_ERROR;
        for (size_t i = 0; i < n; ++i) in->categories[i] = strdup(categories[i] ? categories[i] : "");
        in->n_categories = n;
    }
    return ST_OK;
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

static Status get_state(Inst *in, void **state)
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
    h->mode = in->mode;
    if (st <= ST_WARNING) *state = h;
    else if (!*state) free(h);
    return st;
}

static Status set_state(Inst *in, void *state)
{
    StateHandle *h = state_handle(in, state, "set FMU state");
    if (!h) return ST_ERROR;
    Status st = call(in, "_set_fmu_state", NULL, NULL, "(O)", h->state);
    if (st <= ST_WARNING && h->mode) in->mode = h->mode; /* back in the call state it was taken in */
    return st;
}

static Status free_state(Inst *in, void **state)
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

static Status serialized_size(Inst *in, void *state, size_t *size)
{
    StateHandle *h = state_handle(in, state, "serialized FMU state size");
    if (!h) return ST_ERROR;
    Status st = call(in, "_fmu_state_to_bytes", keep_bytes, h, "(O)", h->state);
    if (st <= ST_WARNING) {
        GIL g = py.PyGILState_Ensure();
        *size = (size_t)py.PyBytes_Size(h->bytes);
        py.PyErr_Clear();
        py.PyGILState_Release(g);
    }
    return st;
}

static Status serialize(Inst *in, void *state, char *bytes, size_t size)
{
    StateHandle *h = state_handle(in, state, "serialize FMU state");
    size_t n = 0;
    if (!h) return ST_ERROR;
    if (!h->bytes) {
        Status st = serialized_size(in, state, &n);
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

static Status deserialize(Inst *in, const char *bytes, size_t size, void **state)
{
    StateHandle *h = calloc(1, sizeof *h);
    if (!h) return ST_ERROR;
    h->magic = STATE_MAGIC;
    GIL g = py.PyGILState_Ensure();
    PyObject *b = py.PyBytes_FromStringAndSize(bytes, (Py_ssize_t_)size);
    py.PyGILState_Release(g);
    Status st = call(in, "_fmu_state_from_bytes", keep_state, h, "(N)", b);
    if (st <= ST_WARNING) *state = h;
    else free(h);
    return st;
}

/* start time, stop time and tolerance to the Python side (None where not defined) */
static Status setup_experiment(Inst *in, int tolerance_defined, double tolerance, double start, int stop_defined,
                               double stop_time, const char *function)
{
    if (tolerance_defined && !(tolerance > 0 && tolerance < HUGE_VAL)) {
        char text[300];
        snprintf(text, sizeof text, "%s refused: tolerance = %g violates the rule: with toleranceDefined the "
                 "tolerance is a number > 0 and finite", function, tolerance);
        emit(in, ST_ERROR, "logStatusError", text);
        return ST_ERROR;
    }
    GIL g = py.PyGILState_Ensure();
    PyObject *stop = stop_defined ? py.PyFloat_FromDouble(stop_time) : (py.Py_IncRef(py.none), py.none);
    PyObject *tol = tolerance_defined ? py.PyFloat_FromDouble(tolerance) : (py.Py_IncRef(py.none), py.none);
    py.PyGILState_Release(g);
    return call(in, "setup_experiment", NULL, NULL, "(dNN)", start, stop, tol);
}

static Status unsupported(Inst *in, const char *what)
{
    char msg[256];
    snprintf(msg, sizeof msg, "%s is not supported by this FMU", what);
    if (in) emit(in, ST_ERROR, "logStatusError", msg);
    return ST_ERROR;
}

#define INST ((Inst *)c)
#define CHECK(c) do { if (!(c)) return ST_ERROR; } while (0)
/* the call-state check of an entry point, and the state a successful call leads to */
#define REQUIRE(rule, function) do { if (!allowed(INST, RULE_##rule, function)) return ST_ERROR; } while (0)
#define LEADS_TO(st, m) do { if ((st) <= ST_WARNING) INST->mode = (m); } while (0)

/* ============================================================================================
 * FMI 2.0 co-simulation
 * ========================================================================================== */
#if POGOFMU_FMI == 2

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[])
{
    CHECK(c);
    REQUIRE(fmi2SetDebugLogging, "fmi2SetDebugLogging");
    return set_logging(INST, loggingOn, nCategories, categories, "fmi2SetDebugLogging");
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Inst *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->name = strdup(instanceName ? instanceName : "");
    if (functions) in->cb = *functions;
    in->logging_on = loggingOn;
    if (fmuType != fmi2CoSimulation) {
        emit(in, fmi2Error, "logStatusError", "this FMU implements FMI 2.0 co-simulation only (fmuType must be fmi2CoSimulation)");
        free_inst(in);
        return NULL;
    }
    return instantiate(in, fmuResourceLocation, fmuGUID, visible, "cs", 0, 0);
}

void fmi2FreeInstance(fmi2Component c)
{
    free_inst(INST);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    CHECK(c);
    REQUIRE(fmi2SetupExperiment, "fmi2SetupExperiment");
    return setup_experiment(INST, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime, "fmi2SetupExperiment");
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2EnterInitializationMode, "fmi2EnterInitializationMode");
    Status st = call(INST, "enter_initialization_mode", NULL, NULL, NULL);
    LEADS_TO(st, MODE_INITIALIZATION);
    return st;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2ExitInitializationMode, "fmi2ExitInitializationMode");
    Status st = call(INST, "exit_initialization_mode", NULL, NULL, NULL);
    LEADS_TO(st, MODE_STEP);
    return st;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2Terminate, "fmi2Terminate");
    Status st = call(INST, "terminate", NULL, NULL, NULL);
    LEADS_TO(st, MODE_TERMINATED);
    return st;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2Reset, "fmi2Reset");
    INST->dead = 0; /* a reset instance starts over */
    Status st = call(INST, "reset", NULL, NULL, NULL);
    LEADS_TO(st, MODE_INSTANTIATED);
    return st;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetReal");
    if (from_buffer(INST, vr, nvr, 'd', value)) return fmi2OK;
    return get_values(INST, "get_real", 'd', vr, nvr, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetInteger");
    if (from_buffer(INST, vr, nvr, 'i', value)) return fmi2OK;
    return get_values(INST, "get_integer", 'i', vr, nvr, value);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetBoolean");
    return get_values(INST, "get_boolean", 'b', vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    CHECK(c);
    REQUIRE(fmi2GetValues, "fmi2GetString");
    return get_values(INST, "get_string", 's', vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetReal");
    return set_values(INST, "set_real", 'd', vr, nvr, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetInteger");
    return set_values(INST, "set_integer", 'i', vr, nvr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetBoolean");
    return set_values(INST, "set_boolean", 'b', vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    CHECK(c);
    REQUIRE(fmi2SetValues, "fmi2SetString");
    return set_values(INST, "set_string", 's', vr, nvr, value);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    CHECK(c && FMUstate);
    REQUIRE(fmi2FMUstate, "fmi2GetFMUstate");
    return get_state(INST, FMUstate);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2SetFMUstate");
    return set_state(INST, FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    CHECK(c);
    REQUIRE(fmi2FMUstate, "fmi2FreeFMUstate");
    return free_state(INST, FMUstate);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    CHECK(c && size);
    REQUIRE(fmi2FMUstate, "fmi2SerializedFMUstateSize");
    return serialized_size(INST, FMUstate, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    CHECK(c && serializedState);
    REQUIRE(fmi2FMUstate, "fmi2SerializeFMUstate");
    return serialize(INST, FMUstate, serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate)
{
    CHECK(c && serializedState && FMUstate);
    REQUIRE(fmi2FMUstate, "fmi2DeSerializeFMUstate");
    return deserialize(INST, serializedState, size, FMUstate);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    CHECK(c);
    REQUIRE(fmi2GetDirectionalDerivative, "fmi2GetDirectionalDerivative");
    return unsupported(INST, "fmi2GetDirectionalDerivative (providesDirectionalDerivative = false)");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    CHECK(c);
    REQUIRE(fmi2SetRealInputDerivatives, "fmi2SetRealInputDerivatives");
    return unsupported(INST, "fmi2SetRealInputDerivatives (canInterpolateInputs = false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    CHECK(c);
    REQUIRE(fmi2GetRealOutputDerivatives, "fmi2GetRealOutputDerivatives");
    return unsupported(INST, "fmi2GetRealOutputDerivatives (maxOutputDerivativeOrder = 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    CHECK(c);
    REQUIRE(fmi2DoStep, "fmi2DoStep");
    Status st = step_call(INST, "do_step", step_result, NULL, currentCommunicationPoint, communicationStepSize);
    if (st == fmi2Discard) INST->mode = MODE_STEP_FAILED;
    return st;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    CHECK(c);
    REQUIRE(fmi2CancelStep, "fmi2CancelStep");
    return unsupported(INST, "fmi2CancelStep (fmi2DoStep never returns fmi2Pending)");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetStatus");
    return unsupported(INST, "fmi2GetStatus (fmi2DoStep never returns fmi2Pending)");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    CHECK(c && value);
    REQUIRE(fmi2GetStatus, "fmi2GetRealStatus");
    if (s != fmi2LastSuccessfulTime) return unsupported(INST, "fmi2GetRealStatus for this status kind");
    return call(INST, "get_status", read_double, value, "(s)", "last_successful_time");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetIntegerStatus");
    return unsupported(INST, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    CHECK(c && value);
    REQUIRE(fmi2GetStatus, "fmi2GetBooleanStatus");
    if (s != fmi2Terminated) return unsupported(INST, "fmi2GetBooleanStatus for this status kind");
    return call(INST, "get_status", read_bool, value, "(s)", "terminated");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    CHECK(c);
    REQUIRE(fmi2GetStatus, "fmi2GetStringStatus");
    return unsupported(INST, "fmi2GetStringStatus");
}

#endif /* POGOFMU_FMI == 2 */

/* ============================================================================================
 * FMI 3.0 model exchange and co-simulation
 * ========================================================================================== */
#if POGOFMU_FMI == 3

/* A tuple of flags (and a trailing double) returned by the Python side: fmi3DoStep,
 * fmi3UpdateDiscreteStates, fmi3CompletedIntegratorStep.  NULL pointers are skipped. */
typedef struct {
    int nb;
    fmi3Boolean *b[5];
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

static Status get_array(Inst *in, const char *method, double out[], size_t n)
{
    Values v = {'d', n, out};
    return call(in, method, read_values, &v, NULL);
}

static Status no_type(Inst *in, const char *function, const char *type, size_t nvr, const VR vr[])
{
    if (nvr == 0) return ST_OK;
    char msg[256];
    snprintf(msg, sizeof msg, "%s: value reference %u is not a variable of type %s (this FMU has Float64 and "
             "Int32 variables only)", function, (unsigned)vr[0], type);
    if (in) emit(in, ST_ERROR, "logStatusError", msg);
    return ST_ERROR;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[])
{
    CHECK(c);
    REQUIRE(fmi3SetDebugLogging, "fmi3SetDebugLogging");
    return set_logging(INST, loggingOn, nCategories, categories, "fmi3SetDebugLogging");
}

static Inst *new_inst(fmi3String instanceName, fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
                      fmi3LogMessageCallback log)
{
    Inst *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->name = strdup(instanceName ? instanceName : "");
    in->env = env;
    in->log = log;
    in->logging_on = loggingOn;
    return in;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    Inst *in = new_inst(instanceName, loggingOn, instanceEnvironment, logMessage);
    if (!in) return NULL;
    in->me = 1;
    return instantiate(in, resourcePath, instantiationToken, visible, "me", 0, 0);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Inst *in = new_inst(instanceName, loggingOn, instanceEnvironment, logMessage);
    if (!in) return NULL;
    if (nRequiredIntermediateVariables > 0) {
        emit(in, ST_ERROR, "logStatusError", "fmi3InstantiateCoSimulation: intermediate variable access is not "
             "supported (nRequiredIntermediateVariables must be 0)");
        free_inst(in);
        return NULL;
    }
    in->event_mode_used = eventModeUsed != 0;
    return instantiate(in, resourcePath, instantiationToken, visible, "cs", eventModeUsed, earlyReturnAllowed);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution is not supported by this FMU (model exchange and "
                   "co-simulation only)");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c) { free_inst(INST); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    CHECK(c);
    REQUIRE(fmi3EnterInitializationMode, "fmi3EnterInitializationMode");
    Status st = setup_experiment(INST, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime,
                                 "fmi3EnterInitializationMode");
    if (st > ST_WARNING) return st;
    Status st2 = call(INST, "enter_initialization_mode", NULL, NULL, NULL);
    st = st2 > st ? st2 : st;
    LEADS_TO(st, MODE_INITIALIZATION);
    return st;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3ExitInitializationMode, "fmi3ExitInitializationMode");
    Status st = call(INST, "exit_initialization_mode", NULL, NULL, NULL);
    /* model exchange, and co-simulation with eventModeUsed, go on in Event Mode */
    LEADS_TO(st, (INST->me || INST->event_mode_used) ? MODE_EVENT : MODE_STEP);
    return st;
}

fmi3Status fmi3EnterEventMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3EnterEventMode, "fmi3EnterEventMode");
    if (!INST->me && !INST->event_mode_used) {
        emit(INST, ST_ERROR, "logStatusError", "fmi3EnterEventMode refused: this co-simulation instance was "
             "instantiated with eventModeUsed = false (it handles its events inside fmi3DoStep)");
        return ST_ERROR;
    }
    Status st = call(INST, "enter_event_mode", NULL, NULL, NULL);
    LEADS_TO(st, MODE_EVENT);
    return st;
}

fmi3Status fmi3Terminate(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3Terminate, "fmi3Terminate");
    Status st = call(INST, "terminate", NULL, NULL, NULL);
    LEADS_TO(st, MODE_TERMINATED);
    return st;
}

fmi3Status fmi3Reset(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3Reset, "fmi3Reset");
    INST->dead = 0; /* a reset instance starts over */
    Status st = call(INST, "reset", NULL, NULL, NULL);
    LEADS_TO(st, MODE_INSTANTIATED);
    return st;
}

/* ---- variables --------------------------------------------------------------------------- */

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetFloat64");
    if (nValues != nvr) return unsupported(INST, "fmi3GetFloat64 with nValues != nValueReferences (arrays)");
    if (from_buffer(INST, vr, nvr, 'd', values)) return ST_OK;
    return get_values(INST, "get_real", 'd', vr, nvr, values);
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetInt32");
    if (nValues != nvr) return unsupported(INST, "fmi3GetInt32 with nValues != nValueReferences (arrays)");
    if (from_buffer(INST, vr, nvr, 'i', values)) return ST_OK;
    return get_values(INST, "get_integer", 'i', vr, nvr, values);
}

fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetBoolean");
    return get_values(INST, "get_boolean", 'b', vr, nvr, values);
}

fmi3Status fmi3GetString(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3String values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3GetValues, "fmi3GetString");
    return get_values(INST, "get_string", 's', vr, nvr, values);
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3SetFloat, "fmi3SetFloat64");
    if (nValues != nvr) return unsupported(INST, "fmi3SetFloat64 with nValues != nValueReferences (arrays)");
    return set_values(INST, "set_real", 'd', vr, nvr, values);
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3SetDiscrete, "fmi3SetInt32");
    if (nValues != nvr) return unsupported(INST, "fmi3SetInt32 with nValues != nValueReferences (arrays)");
    return set_values(INST, "set_integer", 'i', vr, nvr, values);
}

fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Boolean values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3SetDiscrete, "fmi3SetBoolean");
    return set_values(INST, "set_boolean", 'b', vr, nvr, values);
}

fmi3Status fmi3SetString(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3String values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3SetDiscrete, "fmi3SetString");
    return set_values(INST, "set_string", 's', vr, nvr, values);
}

/* types this FMU has no variables of: an error naming the function and the value reference */
#define NO_TYPE_GET(T, CT)                                                                            \
    fmi3Status fmi3Get##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, CT values[], size_t nValues) \
    { return no_type(INST, "fmi3Get" #T, #T, nvr, vr); }
#define NO_TYPE_SET(T, CT)                                                                            \
    fmi3Status fmi3Set##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const CT values[], size_t nValues) \
    { return no_type(INST, "fmi3Set" #T, #T, nvr, vr); }
#define NO_TYPE(T, CT) NO_TYPE_GET(T, CT) NO_TYPE_SET(T, CT)
NO_TYPE(Float32, fmi3Float32)
NO_TYPE(Int8, fmi3Int8)
NO_TYPE(UInt8, fmi3UInt8)
NO_TYPE(Int16, fmi3Int16)
NO_TYPE(UInt16, fmi3UInt16)
NO_TYPE(UInt32, fmi3UInt32)
NO_TYPE(Int64, fmi3Int64)
NO_TYPE(UInt64, fmi3UInt64)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    return no_type(INST, "fmi3GetBinary", "Binary", nvr, vr);
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    return no_type(INST, "fmi3SetBinary", "Binary", nvr, vr);
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{
    return no_type(INST, "fmi3GetClock", "Clock", nvr, vr);
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{
    return no_type(INST, "fmi3SetClock", "Clock", nvr, vr);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference valueReference, size_t *nDependencies)
{
    return unsupported(INST, "fmi3GetNumberOfVariableDependencies (the model description lists the dependencies)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    return unsupported(INST, "fmi3GetVariableDependencies (the model description lists the dependencies)");
}

/* ---- FMU states -------------------------------------------------------------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *FMUState)
{
    CHECK(c && FMUState);
    REQUIRE(fmi3FMUState, "fmi3GetFMUState");
    return get_state(INST, FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState FMUState)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3SetFMUState");
    return set_state(INST, FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *FMUState)
{
    CHECK(c);
    REQUIRE(fmi3FMUState, "fmi3FreeFMUState");
    return free_state(INST, FMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState FMUState, size_t *size)
{
    CHECK(c && size);
    REQUIRE(fmi3FMUState, "fmi3SerializedFMUStateSize");
    return serialized_size(INST, FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size)
{
    CHECK(c && serializedState);
    REQUIRE(fmi3FMUState, "fmi3SerializeFMUState");
    return serialize(INST, FMUState, (char *)serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size, fmi3FMUState *FMUState)
{
    CHECK(c && serializedState && FMUState);
    REQUIRE(fmi3FMUState, "fmi3DeserializeFMUState");
    return deserialize(INST, (const char *)serializedState, size, FMUState);
}

/* ---- not provided ------------------------------------------------------------------------ */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    CHECK(c);
    REQUIRE(fmi3GetDirectionalDerivative, "fmi3GetDirectionalDerivative");
    return unsupported(INST, "fmi3GetDirectionalDerivative (providesDirectionalDerivative = false)");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    CHECK(c);
    REQUIRE(fmi3GetDirectionalDerivative, "fmi3GetAdjointDerivative");
    return unsupported(INST, "fmi3GetAdjointDerivative (providesAdjointDerivatives = false)");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance c)
{
    return unsupported(INST, "fmi3EnterConfigurationMode (this FMU has no structural parameters)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance c)
{
    return unsupported(INST, "fmi3ExitConfigurationMode (this FMU has no structural parameters)");
}

#define NO_CLOCKS(call_) return unsupported(INST, call_ " (this FMU has no clocks)")
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) { NO_CLOCKS("fmi3GetIntervalDecimal"); }
fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) { NO_CLOCKS("fmi3GetIntervalFraction"); }
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 shifts[]) { NO_CLOCKS("fmi3GetShiftDecimal"); }
fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) { NO_CLOCKS("fmi3GetShiftFraction"); }
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 intervals[]) { NO_CLOCKS("fmi3SetIntervalDecimal"); }
fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) { NO_CLOCKS("fmi3SetIntervalFraction"); }
fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 shifts[]) { NO_CLOCKS("fmi3SetShiftDecimal"); }
fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) { NO_CLOCKS("fmi3SetShiftFraction"); }
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) { NO_CLOCKS("fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clockReference, fmi3Float64 activationTime)
{
    return unsupported(INST, "fmi3ActivateModelPartition (scheduled execution is not supported)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues)
{
    CHECK(c);
    REQUIRE(fmi3GetOutputDerivatives, "fmi3GetOutputDerivatives");
    return unsupported(INST, "fmi3GetOutputDerivatives (maxOutputDerivativeOrder = 0)");
}

/* ---- event mode (both interfaces) -------------------------------------------------------- */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    CHECK(c);
    REQUIRE(fmi3UpdateDiscreteStates, "fmi3UpdateDiscreteStates");
    Flags f = {5, {discreteStatesNeedUpdate, terminateSimulation, nominalsOfContinuousStatesChanged,
                   valuesOfContinuousStatesChanged, nextEventTimeDefined}, nextEventTime};
    return call(INST, "update_discrete_states", read_flags, &f, NULL);
}

/* ---- model exchange ---------------------------------------------------------------------- */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3EnterContinuousTimeMode, "fmi3EnterContinuousTimeMode");
    Status st = call(INST, "enter_continuous_time_mode", NULL, NULL, NULL);
    LEADS_TO(st, MODE_CONTINUOUS);
    return st;
}

/* A count an importer passes must be the FMU's: the message names both. */
static int right_count(Inst *in, const char *function, const char *arg, size_t given, size_t have, const char *what)
{
    if (given == have) return 1;
    char text[300];
    snprintf(text, sizeof text, "%s refused: %s = %zu, and this FMU has %s = %zu", function, arg, given, what, have);
    emit(in, ST_ERROR, "logStatusError", text);
    return 0;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    CHECK(c);
    REQUIRE(fmi3CompletedIntegratorStep, "fmi3CompletedIntegratorStep");
    Flags f = {2, {enterEventMode, terminateSimulation}, NULL};
    return call(INST, "completed_integrator_step", read_flags, &f, NULL);
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time)
{
    CHECK(c);
    REQUIRE(fmi3SetTime, "fmi3SetTime");
    return call(INST, "set_time", NULL, NULL, "(d)", time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3SetContinuousStates, "fmi3SetContinuousStates");
    if (!right_count(INST, "fmi3SetContinuousStates", "nContinuousStates", nContinuousStates, INST->nx, "nx"))
        return ST_ERROR;
    GIL g = py.PyGILState_Ensure();
    PyObject *x = value_list('d', continuousStates, nContinuousStates);
    py.PyGILState_Release(g);
    return call(INST, "set_continuous_states", NULL, NULL, "(N)", x);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetContinuousStateDerivatives");
    if (!right_count(INST, "fmi3GetContinuousStateDerivatives", "nContinuousStates", nContinuousStates, INST->nx, "nx")) return ST_ERROR;
    return get_array(INST, "get_derivatives", derivatives, nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetEventIndicators");
    if (!right_count(INST, "fmi3GetEventIndicators", "nEventIndicators", nEventIndicators, INST->nz, "nz")) return ST_ERROR;
    return get_array(INST, "get_event_indicators", eventIndicators, nEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetContinuousStates");
    if (!right_count(INST, "fmi3GetContinuousStates", "nContinuousStates", nContinuousStates, INST->nx, "nx")) return ST_ERROR;
    return get_array(INST, "get_continuous_states", continuousStates, nContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t nContinuousStates)
{
    CHECK(c);
    REQUIRE(fmi3GetContinuous, "fmi3GetNominalsOfContinuousStates");
    if (!right_count(INST, "fmi3GetNominalsOfContinuousStates", "nContinuousStates", nContinuousStates, INST->nx, "nx")) return ST_ERROR;
    return get_array(INST, "get_nominals", nominals, nContinuousStates);
}

static int read_size(Inst *in, PyObject *r, void *ctx)
{
    (void)in;
    *(size_t *)ctx = (size_t)py.PyLong_AsLong(r);
    return ST_OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *nEventIndicators)
{
    CHECK(c && nEventIndicators);
    REQUIRE(fmi3GetNumbers, "fmi3GetNumberOfEventIndicators");
    return call(INST, "number_of_event_indicators", read_size, nEventIndicators, NULL);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *nContinuousStates)
{
    CHECK(c && nContinuousStates);
    REQUIRE(fmi3GetNumbers, "fmi3GetNumberOfContinuousStates");
    return call(INST, "number_of_continuous_states", read_size, nContinuousStates, NULL);
}

/* ---- co-simulation ----------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance c)
{
    CHECK(c);
    REQUIRE(fmi3EnterStepMode, "fmi3EnterStepMode");
    Status st = call(INST, "enter_step_mode", NULL, NULL, NULL);
    LEADS_TO(st, MODE_STEP);
    return st;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    CHECK(c);
    REQUIRE(fmi3DoStep, "fmi3DoStep");
    Flags f = {3, {eventHandlingNeeded, terminateSimulation, earlyReturn}, lastSuccessfulTime};
    return step_call(INST, "do_step3", read_flags, &f, currentCommunicationPoint, communicationStepSize);
}

#endif /* POGOFMU_FMI == 3 */
