"""The resource location as importers pass it: FMI 2.0's fmuResourceLocation as a file URI or, as
some hosts pass it, "file://" + the raw path (a folder named with '%' and hex digits, '#', a space
or non-ASCII loads, and "a%20b" is not taken for "a b"); FMI 3.0's resourcePath as a file system
path, '%' a plain character in it; a wrong location refused naming the argument and every file
that was tried.

References: RFC 8089 file URIs against the raw paths (the folders are named to tell them apart),
the C host tests/c_host/fmi2_host.c (support.c_host_run) and the FMU's own fmi2Instantiate.
"""
import zipfile

import pytest

from support import DIST, STEP, RawInstance
from support import c_host_run as _c_host_run
from support import fmi_function as _fn

# folder names a file URI has to percent-encode; importers pass them raw too ("file://" + path)
AWKWARD_FOLDERS = ["50%ab", "a%20b", "x#y ö 100%"]


@pytest.mark.parametrize("folder", AWKWARD_FOLDERS)
def test_a_raw_resource_location_of_any_folder_name_is_accepted(tmp_path, folder):
    """The C host passes "file://" + the path unencoded: a folder whose name holds '%' followed by
    hex digits (not an escape there), '#', a space or non-ASCII loads — and "a%20b" is not taken
    for a folder "a b" (none exists here)."""
    target = tmp_path / folder
    with zipfile.ZipFile(DIST / "PogoStick.fmu") as z:
        z.extractall(target)
    proc = _c_host_run(tmp_path, target)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert len(proc.stdout.splitlines()) == 11


@pytest.mark.parametrize("folder", AWKWARD_FOLDERS)
def test_an_fmi3_resource_path_is_a_path_not_a_uri(folder, tmp_path):
    """FMI 3.0 passes resourcePath as a file system path: '%' in it is a plain character."""
    target = tmp_path / folder
    with zipfile.ZipFile(DIST / "fmi3" / "PogoStick.fmu") as z:
        z.extractall(target)
    inst = RawInstance("", 3, "cs", unzip_dir=str(target))
    try:
        inst.reach(STEP)
    finally:
        inst.close()


def test_a_wrong_resource_location_names_the_argument_and_what_was_tried(tmp_path):
    import ctypes

    target = tmp_path / "fmu"
    with zipfile.ZipFile(DIST / "PogoStick.fmu") as z:
        z.extractall(target)
    inst = RawInstance("", 2, unzip_dir=str(target))
    try:
        from fmpy.fmi2 import fmi2CallbackFunctions

        location = f"file://{tmp_path}/no%20such/resources".encode()
        fn = _fn(inst, "fmi2Instantiate", ctypes.c_void_p)
        fn.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p,
                       ctypes.POINTER(fmi2CallbackFunctions), ctypes.c_int, ctypes.c_int]
        assert fn(b"wrong", 1, inst.fmu.guid.encode(), location, ctypes.byref(inst._cb), 0, 0) is None
        text = inst.last().replace("%%", "%")  # (an FMI 2.0 log message is a printf format)
        assert f"fmuResourceLocation = '{location.decode()}'" in text, text
        assert f"{tmp_path}/no such/resources/pogofmu_launch.txt" in text, text  # decoded, as a URI
        assert f"{tmp_path}/no%20such/resources/pogofmu_launch.txt" in text, text  # as given
    finally:
        inst.close()
