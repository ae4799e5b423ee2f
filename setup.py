"""The package build compiles the host-side libraries (the engine the host tools run, the SSP
master's C level) and, on Linux, the Python-hosted FMUs' launchers (FMI 2.0 and 3.0) into
pogofmu/_lib, so an installed package carries them; the compiler is the system's cc, gcc or
clang, else the ziglang package's zig cc (a build requirement). It also copies the C layer
(fmu_src/native, which the exporter compiles the FMUs' binaries from) into the package as
pogofmu/_native, and the segmented mirror's model files (examples/segmented_mirror/) beside
``pogofmu mirror``'s builder.  Everything else is in pyproject.toml.

The C layer is copied here rather than mapped with ``package-dir``: a second mapping makes
setuptools' editable install a meta path finder that prints an "Editable installation" warning at
every ``pip install -e`` (python3 tasks.py's install), and a checkout reads fmu_src/native itself."""
import shutil
import sys
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent


def copy_c_layer(into: Path) -> None:
    """The whole C layer, as MANIFEST.in grafts it into a source distribution (codegen/build.py's
    native_dir finds it in an installed package)."""
    native = HERE / "fmu_src" / "native"
    if not (native / "pg_backend.h").is_file():  # (a package without it could export no FMU)
        raise SystemExit(f"setup.py: the C layer {native} is missing (MANIFEST.in carries it into an sdist)")
    shutil.rmtree(into, ignore_errors=True)
    shutil.copytree(native, into, ignore=shutil.ignore_patterns("__pycache__", "*.py[cod]"))


class BuildPyWithHostLibraries(build_py):
    def run(self):
        # setuptools keeps build/lib between builds: a file since deleted from the sources (a C file
        # of the C layer, a module) would go into the wheel again; the package is copied anew
        shutil.rmtree(Path(self.build_lib) / "pogofmu", ignore_errors=True)
        super().run()
        if self.editable_mode:  # an editable checkout compiles them on first use (the cache)
            return
        copy_c_layer(Path(self.build_lib) / "pogofmu" / "_native")
        sys.path.insert(0, str(HERE / "fmu_src"))
        try:
            from pogofmu.codegen import build
            from pogofmu.exporter import python_fmu
        finally:
            sys.path.pop(0)
        into = Path(self.build_lib) / "pogofmu" / "_lib"
        shutil.rmtree(into, ignore_errors=True)  # (setuptools keeps build/ between builds: no stale library)
        build.host_engine_library(into=into)
        build.host_level_library(into=into)
        if sys.platform.startswith("linux"):  # the Python-hosted FMUs' binary: Linux (docs/using-fmus.md)
            for version in (2, 3):
                python_fmu.compile_launcher(version, into=into)
        # the segmented mirror's model files (pogofmu mirror builds its system from them): a checkout
        # has them in examples/, an installed package beside the builder
        models = Path(self.build_lib) / "pogofmu" / "studies" / "segmented_mirror"
        shutil.rmtree(models, ignore_errors=True)
        models.mkdir(parents=True)
        mirror = sorted((HERE / "examples" / "segmented_mirror").glob("*.py"))
        if not mirror:
            raise SystemExit("setup.py: examples/segmented_mirror/ is missing (MANIFEST.in carries it into an sdist)")
        for f in mirror:
            shutil.copy2(f, models / f.name)


class BinaryDistribution(Distribution):
    def has_ext_modules(self):  # a wheel for this platform: it carries compiled libraries
        return True


setup(cmdclass={"build_py": BuildPyWithHostLibraries}, distclass=BinaryDistribution)
