/* nte_real.c -- the functions of nte_real.h that are not inline (see there): exp and the
 * int64 conversion. */
#include "nte_real.h"

/*
 * (nte_real_t) x, correctly rounded (to nearest, ties to even).  The float build does it with
 * integer operations beyond the int32 range: on a single-precision FPU the int64 cast links
 * libgcc's soft-float conversion and, through it, its soft-float addition, 630 B of the
 * board's 32 KiB of flash for two call sites that almost never leave the int32 range (a
 * sample gap or an insertion longer than 35 min).  The same bits as the cast
 * (tests/c/test_model.c compares them around every power of two and at the ties).
 */
nte_real_t nte_real_from_i64(const int64_t x)
{
#if NTE_DOUBLE
    return (nte_real_t)x;
#else
    if ((x >= (int64_t)INT32_MIN) && (x <= (int64_t)INT32_MAX)) {
        return (nte_real_t)(int32_t)x; /* one VCVT, correctly rounded */
    }
    const bool negative = x < 0;
    const uint64_t m = negative ? (0U - (uint64_t)x) : (uint64_t)x; /* >= 2^31 */
    uint32_t e = 63U;                                               /* m's leading bit */
    while ((m >> e) == 0U) {
        e--;
    }
    const uint32_t drop = e - 23U; /* 24 significant bits kept */
    uint64_t keep = m >> drop;
    const uint64_t rest = m & ((((uint64_t)1U) << drop) - 1U);
    const uint64_t half = ((uint64_t)1U) << (drop - 1U);
    if ((rest > half) || ((rest == half) && ((keep & 1U) != 0U))) {
        keep++;
    }
    if ((keep >> 24U) != 0U) { /* rounded up to 2^24: one more exponent */
        keep >>= 1U;
        e++;
    }
    const uint32_t bits = (negative ? 0x80000000U : 0U) | ((e + 127U) << 23U) |
                          ((uint32_t)keep & 0x7FFFFFU);
    nte_real_t out;
    memcpy(&out, &bits, sizeof out);
    return out;
#endif
}

/*
 * exp(x), |x| clamped to NTE_K_EXP_XMAX: reference_py/fmath.py Real.exp operation for
 * operation.  Not inline: every depth term, RK3 stage, parameter and tanh takes one, and two
 * dozen inlined copies cost the board about 1.8 KiB of its 32 KiB of flash for a call's few
 * cycles.
 */
nte_real_t nte_exp(nte_real_t x)
{
    static const nte_real_t coeffs[NTE_K_EXP_DEGREE + 1] = NTE_K_EXP_COEFFS;
    if (isnan(x)) {
        return x;
    }
    if (x > NTE_K_EXP_XMAX) {
        x = NTE_K_EXP_XMAX;
    }
    if (x < -NTE_K_EXP_XMAX) {
        x = -NTE_K_EXP_XMAX;
    }
    nte_real_t t = x * NTE_K_EXP_LOG2E;
    t = (t >= NTE_C(0.0)) ? (t + NTE_C(0.5)) : (t - NTE_C(0.5));
    const int32_t n = (int32_t)t;
    const nte_real_t nf = (nte_real_t)n;
    const nte_real_t r = (x - (nf * NTE_K_EXP_LN2_HI)) - (nf * NTE_K_EXP_LN2_LO);
    /* Horner from the top coefficient down, the loop written out (NTE_UNROLL): every depth
     * term and RK3 stage takes an exp */
    nte_real_t p = coeffs[NTE_K_EXP_DEGREE];
    NTE_UNROLL
    for (int i = NTE_K_EXP_DEGREE - 1; i >= 0; i--) {
        p = (p * r) + coeffs[i];
    }
    return p * nte_pow2(n);
}
