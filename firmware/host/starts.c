/* Starting values away from the truth: reference_py/starts.py in C, bit for bit. */
#include "starts.h"

#include <math.h>

uint64_t nte_splitmix64(uint64_t* state)
{
    *state += 0x9E3779B97F4A7C15ULL;
    uint64_t z = *state;
    z = (z ^ (z >> 30U)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27U)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31U);
}

int nte_start_values(const double values[7], const uint64_t seed, const double factor,
                     const int model, double out[7])
{
    /* identified parameters per model (MODEL_PARAMS), as flags in PARAM_NAMES order */
    static const int moved[2][7] = {{1, 1, 1, 1, 1, 1, 0}, {1, 1, 1, 1, 0, 0, 1}};
    for (int j = 0; j < 7; j++) {
        out[j] = values[j];
    }
    if (seed == 0U) {
        return 0;
    }
    if (!(isfinite(factor) && (factor >= 1.0))) {
        return -1;
    }
    const double log_f = log(factor);
    uint64_t state = seed;
    double mult[7];
    for (int j = 0; j < 7; j++) {
        const uint64_t x = nte_splitmix64(&state);
        const double r = (double)(x >> 11U) * (1.0 / 9007199254740992.0);
        mult[j] = moved[(model == 1) ? 0 : 1][j] ? exp(((2.0 * r) - 1.0) * log_f) : 1.0;
    }
    for (int j = 0; j < 7; j++) {
        out[j] = values[j] * mult[j];
    }
    const double kappa = (values[4] < 0.0) ? 1.0 : 0.0;
    const double excess = values[3] - (kappa * (-values[4]));
    out[3] = (kappa * (-out[4])) + (excess * mult[3]);
    return 0;
}
