/* pogofmu launcher: CPython embedded at run time — the room of the Python-hosted FMUs' binary that
 * finds a libpython >= 3.10 (the host's own, $POGOFMU_PYTHON_LIB, the build's record, the
 * python3 on $PATH, the usual places), resolves the stable-ABI functions it needs by dlsym (no
 * link-time dependency on libpython), starts one isolated interpreter per process, however many
 * copies of the launcher are loaded and from however many threads, and loads the FMU's boot code
 * (resources/pogofmu_boot.py). The FMI entry points are fmu_src/native/fmi2/pg_fmi2.c and
 * fmi3/pg_fmi3.c, over the adapter (adapter/); the model source that uses this file is
 * pg_source_py.c beside it. */
#ifndef POGOFMU_PYTHON_EMBED_H
#define POGOFMU_PYTHON_EMBED_H

#include <stdarg.h>
#include <stddef.h>
#include <wchar.h>


typedef struct _object PyObject;
typedef long Py_ssize_t_;
typedef int GIL;

#define PY_FUNCTIONS(X)                                                                         \
    X(int, Py_IsInitialized, (void))                                                            \
    X(void, Py_InitializeEx, (int))                                                             \
    X(void, Py_SetPythonHome, (const wchar_t *))                                                \
    X(void, Py_SetProgramName, (const wchar_t *))                                               \
    X(wchar_t *, Py_DecodeLocale, (const char *, size_t *))                                     \
    X(const char *, Py_GetVersion, (void))                                                      \
    X(void *, PyEval_SaveThread, (void))                                                        \
    X(GIL, PyGILState_Ensure, (void))                                                           \
    X(void, PyGILState_Release, (GIL))                                                          \
    X(void, Py_IncRef, (PyObject *))                                                            \
    X(void, Py_DecRef, (PyObject *))                                                            \
    X(PyObject *, Py_CompileString, (const char *, const char *, int))                          \
    X(PyObject *, PyEval_EvalCode, (PyObject *, PyObject *, PyObject *))                        \
    X(PyObject *, PyImport_ImportModule, (const char *))                                        \
    X(PyObject *, PyDict_New, (void))                                                           \
    X(int, PyDict_SetItemString, (PyObject *, const char *, PyObject *))                        \
    X(PyObject *, PyDict_GetItemString, (PyObject *, const char *))                             \
    X(PyObject *, PyObject_GetAttrString, (PyObject *, const char *))                           \
    X(int, PyObject_SetAttrString, (PyObject *, const char *, PyObject *))                      \
    X(PyObject *, PyObject_Call, (PyObject *, PyObject *, PyObject *))                          \
    X(PyObject *, PyObject_CallObject, (PyObject *, PyObject *))                                \
    X(PyObject *, PyObject_CallFunctionObjArgs, (PyObject *, ...))                              \
    X(PyObject *, Py_VaBuildValue, (const char *, va_list))                                     \
    X(PyObject *, PyObject_Str, (PyObject *))                                                   \
    X(int, PyObject_IsTrue, (PyObject *))                                                       \
    X(PyObject *, PyTuple_New, (Py_ssize_t_))                                                   \
    X(PyObject *, PyTuple_GetItem, (PyObject *, Py_ssize_t_))                                   \
    X(Py_ssize_t_, PyTuple_Size, (PyObject *))                                                  \
    X(PyObject *, PyList_New, (Py_ssize_t_))                                                    \
    X(int, PyList_SetItem, (PyObject *, Py_ssize_t_, PyObject *))                               \
    X(int, PyList_SetSlice, (PyObject *, Py_ssize_t_, Py_ssize_t_, PyObject *))                 \
    X(PyObject *, PySequence_GetItem, (PyObject *, Py_ssize_t_))                                \
    X(Py_ssize_t_, PySequence_Size, (PyObject *))                                               \
    X(PyObject *, PyLong_FromLong, (long))                                                      \
    X(PyObject *, PyLong_FromUnsignedLong, (unsigned long))                                     \
    X(PyObject *, PyLong_FromLongLong, (long long))                                             \
    X(long, PyLong_AsLong, (PyObject *))                                                        \
    X(long long, PyLong_AsLongLong, (PyObject *))                                               \
    X(unsigned long long, PyLong_AsUnsignedLongLong, (PyObject *))                              \
    X(void *, PyLong_AsVoidPtr, (PyObject *))                                                   \
    X(PyObject *, PyFloat_FromDouble, (double))                                                 \
    X(double, PyFloat_AsDouble, (PyObject *))                                                   \
    X(PyObject *, PyBool_FromLong, (long))                                                      \
    X(PyObject *, PyUnicode_FromString, (const char *))                                         \
    X(PyObject *, PyUnicode_AsUTF8String, (PyObject *))                                         \
    X(char *, PyBytes_AsString, (PyObject *))                                                   \
    X(Py_ssize_t_, PyBytes_Size, (PyObject *))                                                  \
    X(PyObject *, PyBytes_FromStringAndSize, (const char *, Py_ssize_t_))                       \
    X(PyObject *, PyErr_Occurred, (void))                                                       \
    X(void, PyErr_Fetch, (PyObject **, PyObject **, PyObject **))                               \
    X(void, PyErr_NormalizeException, (PyObject **, PyObject **, PyObject **))                  \
    X(int, PyException_SetTraceback, (PyObject *, PyObject *))                                  \
    X(void, PyErr_Clear, (void))

/* data symbols, needed only to start an interpreter of our own (legacy configuration API,
 * present in 3.10-3.13) */
#define PY_FLAGS(X) X(Py_IsolatedFlag) X(Py_NoSiteFlag) X(Py_IgnoreEnvironmentFlag) \
    X(Py_NoUserSiteDirectory) X(Py_DontWriteBytecodeFlag) X(Py_UTF8Mode)

typedef struct {
#define DECLARE(ret, name, args) ret(*name) args;
    PY_FUNCTIONS(DECLARE)
#undef DECLARE
#define DECLARE_FLAG(name) int *name;
    PY_FLAGS(DECLARE_FLAG)
#undef DECLARE_FLAG
    PyObject *none;
} PyApi;

/* the CPython functions, resolved by ensure_python (library-local: built with hidden visibility) */
extern PyApi py;

enum { Py_file_input = 257 };

extern int python_ready;          /* py.* resolved and an interpreter running */
extern char python_report[4096];  /* what was tried, for the error message */
extern PyObject *boot;            /* globals of pogofmu_boot.py (compiled once per process) */

/* Make sure an interpreter runs and the boot code is loaded: 1; 0 no usable interpreter, -1 the
 * boot code cannot be read or run, -2 the process runs a CPython of its own older than 3.10 (its
 * version in python_report); python_report says what was tried or what failed. */
int ensure_python(const char *resources);

#endif
