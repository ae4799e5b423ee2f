"""A minimal FMI 2.0 importer in plain ctypes (no fmpy): instantiate the FMU extracted in the
folder given, print whether an instance came back and every logged message.

Run by the tests under interpreters fmpy does not support (CPython 3.8, 3.9): standard library
only, and the same code under any CPython 3.
Arguments: the extracted FMU's folder, its model identifier.
"""
import ctypes
import re
import sys

root, model = sys.argv[1], sys.argv[2]
with open(root + "/modelDescription.xml", encoding="utf-8") as f:
    guid = re.search(r'guid="([^"]+)"', f.read()).group(1)
lib = ctypes.CDLL(f"{root}/binaries/linux64/{model}.so")
LOGGER = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)
messages = []


class Callbacks(ctypes.Structure):
    _fields_ = [("logger", LOGGER), ("allocateMemory", ctypes.c_void_p), ("freeMemory", ctypes.c_void_p),
                ("stepFinished", ctypes.c_void_p), ("componentEnvironment", ctypes.c_void_p)]


logger = LOGGER(lambda env, name, status, category, message: messages.append(message.decode()))
callbacks = Callbacks(logger, None, None, None, None)
lib.fmi2Instantiate.restype = ctypes.c_void_p
lib.fmi2Instantiate.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p,
                                ctypes.POINTER(Callbacks), ctypes.c_int, ctypes.c_int]
c = lib.fmi2Instantiate(b"ctypes", 1, guid.encode(), f"file://{root}/resources".encode(), ctypes.byref(callbacks), 0, 0)
print("instance" if c else "NULL")
print("\n".join(messages))
