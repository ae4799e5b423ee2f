/* <math.h>, and on the native FMU's Windows build the math functions of the C library (the UCRT),
 * as the Python-hosted FMU's.
 *
 * zig's linker for x86_64-windows-gnu reads its own compiler runtime (compiler_rt.lib, whose exp,
 * log, log10, sin, cos, tan, ... are zig's ports of musl's older fdlibm code) before the UCRT's
 * import libraries, so those functions were linked into the DLL instead of imported, and their last
 * bit differs from the C library's: the Penetrator's z at t = 2.598 under wine (in its default
 * experiment zig's exp differs from x86-64 glibc's in 364 of 3873 calls, the UCRT's in 4).  Declared
 * dllimport, a call goes through the import table (__imp_<name>, which only the UCRT's import
 * library defines) to the UCRT's own function.
 *
 * Only where the build defines POGOFMU_CRT_MATH (pogofmu.codegen.build: its zig build for Windows);
 * elsewhere, a source FMU's build by any other compiler included, this is <math.h> alone.  Every C
 * file that calls one of these functions includes this header (a test checks the DLL's imports). */
#ifndef PG_CRT_MATH_H
#define PG_CRT_MATH_H

#include <math.h>

#if defined(POGOFMU_CRT_MATH) && defined(_WIN32)
#ifdef __clang__
#pragma clang diagnostic push
#pragma clang diagnostic ignored "-Wdll-attribute-on-redeclaration"
#endif
/* every function of inexact result that the engine calls (pg_support.c, pg_engine.c, pg_repr.c) */
__declspec(dllimport) double exp(double);
__declspec(dllimport) double log(double);
__declspec(dllimport) double log10(double);
__declspec(dllimport) double sin(double);
__declspec(dllimport) double cos(double);
__declspec(dllimport) double tan(double);
__declspec(dllimport) double asin(double);
__declspec(dllimport) double acos(double);
__declspec(dllimport) double atan(double);
__declspec(dllimport) double sinh(double);
__declspec(dllimport) double cosh(double);
__declspec(dllimport) double tanh(double);
__declspec(dllimport) double cbrt(double);
__declspec(dllimport) double pow(double, double);
__declspec(dllimport) double atan2(double, double);
__declspec(dllimport) double hypot(double, double);
#ifdef __clang__
#pragma clang diagnostic pop
#endif
#endif

#endif
