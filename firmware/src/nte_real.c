/* nte_real.c -- the one conversion of nte_real.h that is not inline (see there). */
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
