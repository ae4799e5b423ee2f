"""The generator of the native FMUs' C (host-side; never inside an FMU).

* :mod:`.trace` — the tracer: a model's functions called with traced values, every operation
  recorded in Python's order (the derivatives are the runtime's dual numbers over traced values);
* :mod:`.cprint` — the C printer of the recorded operations; :mod:`.cmodel` — a model's C file;
* :mod:`.cpairs` — the Runge–Kutta pairs' C, generated from ``runtime/solver/tableaux.py`` and kept;
* :mod:`.cfmu` — the FMU's variable table; :mod:`.build` — staging and compiling (the C compiler:
  ``cc``/``gcc``/``clang`` on the PATH, else the ziglang package's ``zig cc``), the host libraries.
"""
