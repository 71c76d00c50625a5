/*
 * The working precision and the few primitives every numeric file uses.
 *
 * Only + - * /, comparisons and integer<->float conversions (all correctly rounded IEEE-754
 * operations) appear here, so results are the same bits on every conforming target.  exp and
 * tanh mirror reference_py/fmath.py operation for operation.  Internal header.
 */
#ifndef NTE_REAL_H
#define NTE_REAL_H

#include "nte.h"
#include "nte_constants.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#if NTE_DOUBLE
#define NTE_C(x) (x)
#else
/** A decimal literal in the working precision (exact small numbers only: 0, 0.5, 1, 2, ...). */
#define NTE_C(x) (x##f)
#endif

/** |x| (exact: clears the sign bit, like numpy's abs). */
static inline nte_real_t nte_abs(const nte_real_t x)
{
#if NTE_DOUBLE
    return fabs(x);
#else
    return fabsf(x);
#endif
}

/** Correctly rounded square root (IEEE-754, like numpy's sqrt). */
static inline nte_real_t nte_sqrt(const nte_real_t x)
{
#if NTE_DOUBLE
    return sqrt(x);
#else
    return sqrtf(x);
#endif
}

static inline bool nte_isfinite(const nte_real_t x) { return isfinite(x) != 0; }

/*
 * Loops with a constant trip count of at most 16 that the compiler should write out, and
 * kernels to inline where their size argument is a constant.  On the board a loop's counter,
 * compare and taken branch cost more than the multiply-add they guard; written out, the same
 * operations run in the same order, so with the same bits.  GCC and Clang do it when asked
 * (the board build keeps -fno-inline-functions for flash); another compiler keeps the loops.
 * NTE_OUT_OF_LINE: a kernel the board's cycle model reports as its own row (cycles.py
 * --functions), kept out of its one caller, where the board's link-time optimisation would
 * inline it (a call: a few cycles of the hundreds it costs).
 */
#if defined(__GNUC__)
#define NTE_UNROLL _Pragma("GCC unroll 16")
#define NTE_SPECIALISE static inline __attribute__((always_inline))
#define NTE_OUT_OF_LINE __attribute__((noinline))
#else
#define NTE_UNROLL
#define NTE_SPECIALISE static inline
#define NTE_OUT_OF_LINE
#endif

/**
 * (nte_real_t) x for a time in integer microseconds, correctly rounded (to nearest, ties to
 * even), as numpy's astype (nte_real.c: why not the cast).
 */
nte_real_t nte_real_from_i64(int64_t x);

/** 2^n for n in the normal exponent range, assembled from the exponent bits. */
static inline nte_real_t nte_pow2(const int32_t n)
{
    nte_real_t out;
#if NTE_DOUBLE
    const uint64_t bits = ((uint64_t)(int64_t)(n + 1023)) << 52U;
#else
    const uint32_t bits = ((uint32_t)(n + 127)) << 23U;
#endif
    memcpy(&out, &bits, sizeof out);
    return out;
}

/** exp(x), |x| clamped to NTE_K_EXP_XMAX; reference_py/fmath.py Real.exp (nte_real.c: why
 *  it is not inline). */
nte_real_t nte_exp(nte_real_t x);

/** tanh(x) = sign(x) (1 - e)/(1 + e), e = exp(-2|x|); reference_py/fmath.py Real.tanh. */
static inline nte_real_t nte_tanh(const nte_real_t x)
{
    const nte_real_t a = nte_abs(x);
    const nte_real_t ac = (a > NTE_K_EXP_TANH_XMAX) ? NTE_K_EXP_TANH_XMAX : a;
    const nte_real_t e = nte_exp(-(ac + ac));
    nte_real_t t = (NTE_C(1.0) - e) / (NTE_C(1.0) + e);
    if (a > NTE_K_EXP_TANH_XMAX) {
        t = NTE_C(1.0);
    }
    return (x < NTE_C(0.0)) ? -t : t;
}

#endif /* NTE_REAL_H */
