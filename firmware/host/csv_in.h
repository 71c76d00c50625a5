/*
 * Strict reader of insertion CSV files for the host programs (the C twin of
 * reference_py/tools/csvio.py read_trial).  Host only: uses malloc and double.
 */
#ifndef NTE_CSV_IN_H
#define NTE_CSV_IN_H

#include "nte.h"

#include <stddef.h>

typedef struct nte_trial_t {
    size_t n;
    double* t_s;
    double* depth_mm;
    double* velocity_mm_s;
    double* force_n;
    int velocity_given;
} nte_trial_t;

/** Read `path`.  On error returns -1 and writes "FILE:LINE: ..." (no newline) to err. */
int nte_trial_read(const char* path, nte_trial_t* trial, char* err, size_t err_size);
void nte_trial_free(nte_trial_t* trial);
/** Sample k of the trial as the library takes it: time in integer microseconds,
 * floor(t * 1e6 + 0.5) (csvio.time_us), depth and velocity rounded to nte_real_t, the force
 * too, or 0 when `force_ignored` (--predict-only: the bank is fed 0 N, never rejected). */
void nte_trial_sample(const nte_trial_t* tr, size_t k, int force_ignored, nte_sample_t* s);
/** Central differences in double, one-sided at the ends (csvio.central_difference). */
void nte_central_difference(const double* t, const double* x, size_t n, double* v);
/** Python's repr() of a double (shortest round-trip text). */
void nte_py_repr(double x, char* buf, size_t size);

#endif /* NTE_CSV_IN_H */
