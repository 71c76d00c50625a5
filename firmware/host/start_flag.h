/*
 * --start NAME=VALUE[,NAME=VALUE...] of nte-run: starting (nominal) values of parameters by
 * name, checked as `nte-ref estimate --start` checks them (reference_py/tools/cli.py
 * start_values), with its messages.  Host only.
 */
#ifndef NTE_START_FLAG_H
#define NTE_START_FLAG_H

#include "nte.h"

#include <stddef.h>

typedef struct nte_start_flag_t {
    int given[NTE_PARAM_COUNT]; /**< 1: the value of this parameter (nte_param_id_t) */
    double value[NTE_PARAM_COUNT];
} nte_start_flag_t;

/**
 * Parse the value of --start into out (cleared first).  Every name one of nte_param_name's,
 * once; every value finite: the relaxation strengths in (0, 1), f2 within +-1000, the others
 * in (0, 1000] (NTE_K_RANGE_NOMINAL_ABS_MAX).  Combinations (f1 + f2 > 0, strengths summing
 * below 1) are left to the estimator's configuration check.  Returns 0, or -1 with the reason
 * (what follows "argument --start: ") in msg.
 */
int nte_start_flag_parse(const char* text, nte_start_flag_t* out, char* msg, size_t cap);

#endif /* NTE_START_FLAG_H */
