/*
 * The plausibility check of an insertion in N, s and mm (the C twin of
 * reference_py/tools/units_check.py check_units): a file read in the wrong unit or with the
 * opposite sign is refused with the reference's message, naming the likely unit and the option
 * that converts it.  Host only: uses malloc and double.
 */
#ifndef NTE_UNITS_CHECK_H
#define NTE_UNITS_CHECK_H

#include "csv_in.h"

#include <stddef.h>

/** The estimator's accepted ranges (csvio.Limits, from the configuration). */
typedef struct nte_limits_t {
    double depth_min_mm;
    double depth_max_mm;
    double speed_max_mm_s;
    double force_max_n;
    double dt_max_s;
} nte_limits_t;

/**
 * Check the converted trial read from `path` (units_check.check_units, rule by rule and in its
 * order).  Returns 0 when plausible; -1 with the reference's message (no newline) in err
 * when not, or when memory runs out.
 */
int nte_units_check(const char* path, const nte_trial_t* trial, const nte_units_t* units,
                    const nte_limits_t* limits, char* err, size_t err_size);

#endif /* NTE_UNITS_CHECK_H */
