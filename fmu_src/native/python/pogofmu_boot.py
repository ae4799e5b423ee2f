"""Bootstrap of a pogofmu FMU's Python side, run by the launcher (its model source, pg_source_py.c).

The launcher compiles this file from the FMU's ``resources/`` folder once per process and calls
``hosted(resources, engine, fmi)`` at each instantiation.  It needs the standard library only.

Isolation: the FMU's code lives in ``resources/`` under names private to one build of one model
(``_pogofmu_<Model>_<hash>`` for the package, ``<package>_slave`` for the slave module; written to
``resources/pogofmu_launch.txt`` by build_fmu.py).  They are imported from their files, not
through ``sys.path`` (which stays untouched), so

* two different models, or the same model built from two versions of the project, never see each
  other's modules, nor any ``pogofmu`` the host has imported;
* the same build instantiated again reuses the modules already imported (a sweep of a thousand
  runs imports the code once), even when the folder it was first extracted to has been deleted:
  the package's search path is moved to the new folder, which holds identical files.
"""
import os
import sys
import importlib
import importlib.util
import traceback

LAUNCH_FILE = "pogofmu_launch.txt"


def read_launch_file(resources):
    """``key=value`` lines of resources/pogofmu_launch.txt (keys may repeat: a list of values)."""
    conf = {}
    with open(os.path.join(resources, LAUNCH_FILE), encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith("#"):
                key, _, value = line.partition("=")
                conf.setdefault(key.strip(), []).append(value.strip())
    return conf


def _import_from_file(name, path, package_dir=None):
    module = sys.modules.get(name)
    if module is not None:
        return module
    spec = importlib.util.spec_from_file_location(
        name, path, submodule_search_locations=[package_dir] if package_dir else None)
    if spec is None:
        raise ImportError(f"cannot import {name} from {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def _repoint_package(package, package_dir):
    """The build's modules are already imported, from a folder that may be gone: point the search
    path of the package and its subpackages at this (identical) copy, for any later import."""
    old = sys.modules[package].__path__[0]
    if old == package_dir or os.path.isdir(old):
        return
    for name, module in list(sys.modules.items()):
        if name == package or name.startswith(package + "."):
            paths = getattr(module, "__path__", None)
            if paths:
                paths[:] = [package_dir + p[len(old):] if p.startswith(old) else p for p in paths]


def _process_lock():
    """One lock for the whole process, whichever FMU's copy of this file takes it (each FMU library
    compiles its own): two threads instantiating at once must not both import a build's modules
    (the second saw the first's half-executed module). Created once: dict.setdefault is atomic."""
    lock = getattr(sys, "_pogofmu_boot_lock", None)
    if lock is None:
        import threading

        lock = sys.__dict__.setdefault("_pogofmu_boot_lock", threading.RLock())
    return lock


class BootError(Exception):
    """The FMU's resources cannot give its Python code; the launcher logs the message (Error)."""

    fmi_status = 3


def load(resources, engine=None):
    """The slave class of the FMU whose resources folder is ``resources`` (a path as str or as the
    file system's bytes: any locale); ``engine``: the library that carries the engine (the launcher
    itself). The export checks with it that the staged code imports on its own."""
    if isinstance(resources, bytes):
        resources = os.fsdecode(resources)
    if isinstance(engine, bytes):
        engine = os.fsdecode(engine)
    with _process_lock():
        return _load(resources, engine)


def _load(resources, engine=None):
    try:
        conf = read_launch_file(resources)
        package, module, cls = conf["package"][0], conf["module"][0], conf["class"][0]
    except OSError as exc:
        raise BootError(f"the FMU's resources folder is incomplete: {exc.filename or resources}: "
                        f"{exc.strerror or exc} (extract the FMU again)") from None
    except (KeyError, IndexError, ValueError) as exc:
        raise BootError(f"the FMU's {LAUNCH_FILE} is damaged ({type(exc).__name__}: {exc}): extract the FMU "
                        f"again") from None
    package_dir = os.path.join(resources, package)
    for needed in (os.path.join(package_dir, "__init__.py"), os.path.join(resources, module + ".py")):
        if not os.path.isfile(needed):
            raise BootError(f"the FMU's code is missing: {needed} does not exist (the FMU's resources folder is "
                            f"incomplete: extract the FMU again)")
    if package in sys.modules:
        _repoint_package(package, package_dir)
    _import_from_file(package, os.path.join(package_dir, "__init__.py"), package_dir)
    if engine:
        importlib.import_module(package + ".solver.cengine").use_library(engine)
    slave = _import_from_file(module, os.path.join(resources, module + ".py"))
    return getattr(slave, cls)


def describe(exc):
    """The text the launcher logs for an exception raised by the FMU's Python code: the message of
    an intended error (it carries ``fmi_status``), else type, message and where it was raised."""
    if getattr(exc, "fmi_status", None) is not None:
        return str(exc)
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" (at {os.path.basename(frames[-1].filename)}:{frames[-1].lineno})" if frames else ""
    return f"internal error: {type(exc).__name__}: {exc}{where}"


def hosted(resources, engine, fmi, instance_name=""):
    """The model of the FMU whose resources folder is ``resources``, for the C adapter (the launcher's
    model source, pg_source_py.c): a ``HostedFmu`` of the build's ``hosted`` module, whose
    ``fmu_address`` is the adapter's PgFmu (variable table and PgModel, built at run time),
    ``py_address`` the binding's PgbPy and ``bind(p, s)`` takes the instance's parameters and solver
    settings (addresses of doubles)."""
    if isinstance(resources, bytes):
        resources = os.fsdecode(resources)
    with _process_lock():
        cls = _load(resources, os.fsdecode(engine) if isinstance(engine, bytes) else engine)
        conf = read_launch_file(resources)
        package = conf["package"][0]
        module = importlib.import_module(package + ".hosted")
    return module.HostedFmu(cls.model, int(fmi), conf["token"][0], package, instance_name)
