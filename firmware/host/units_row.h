/*
 * A units row: the record under a header that names each column's unit ("(s)","(mm)","(N)"),
 * the C twin of reference_py/tools/units_row.py (its docstring holds the rules).  The reader
 * (csv_in.c) keeps the read columns' cells of such a row; nte_units_row_check holds them to the
 * units the columns are read in.  Host only.
 */
#ifndef NTE_UNITS_ROW_H
#define NTE_UNITS_ROW_H

#include "csv_in.h"

#include <stddef.h>

/** 1 when the stripped cell s[0..n) names a unit of nte_units.h's tables (or one of its
 *  spellings), bare or in one pair of () or [], ASCII case aside; then *kind is "time",
 *  "depth" or "force" and *unit its name (units_row.unit_of_token).  0 otherwise. */
int nte_unit_of_token(const char* s, size_t n, const char** kind, const char** unit);

/** 1 when the stripped cell s[0..n) reads as a unit in a units row: it names one
 *  (nte_unit_of_token) or it is text in one pair of () or [] (units_row.unit_like). */
int nte_unit_like(const char* s, size_t n);

/** Refuse a trial whose units row gives, for a column read, no unit of its quantity (the
 *  message lists the units read) or another unit than `units` reads it in
 *  (units_row.units_row_check): -1 and the reason in err ("PATH:LINE: column 'NAME': ..."),
 *  else 0. */
int nte_units_row_check(const char* path, const nte_trial_t* trial, const nte_units_t* units,
                        char* err, size_t err_size);

#endif /* NTE_UNITS_ROW_H */
