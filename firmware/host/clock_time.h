/*
 * A time column written as a clock or a calendar reads, in seconds: the C twin of
 * reference_py/tools/clock_time.py (its docstring holds the rules).  A cell is a time of day,
 * H:MM:SS or HH:MM:SS with an optional fraction (a point, or a comma where the cells are not
 * separated by commas), or a date and time, YYYY-MM-DD or YYYY/MM/DD, then 'T' or a space, then
 * such a time and an optional zone (Z, +HH:MM, +HHMM, -...).  It reads as the whole seconds
 * since 1970-01-01 00:00 UTC (a date) or since midnight (a time of day, a day added at each
 * pass over midnight), plus the fraction read as the decimal 0.DIGITS: the reference's bits.
 * Host only.
 */
#ifndef NTE_CLOCK_TIME_H
#define NTE_CLOCK_TIME_H

#include <stddef.h>
#include <stdint.h>

/** At most this many digits of a second's fraction (nanoseconds and far beyond). */
#define NTE_CLOCK_FRACTION_DIGITS_MAX 18U

/** A clock cell read (clock_time.Stamp). */
typedef struct nte_stamp_t {
    int dated;     /**< 1: a date and time, 0: a time of day */
    int64_t whole; /**< whole seconds, since 1970-01-01 00:00 UTC or since midnight, s */
    char fraction[NTE_CLOCK_FRACTION_DIGITS_MAX + 1U]; /**< the fraction's digits, "" none */
} nte_stamp_t;

/** The days a time of day has passed midnight (clock_time.ClockColumn); zero it to start. */
typedef struct nte_clock_column_t {
    int64_t days;
    int64_t previous; /**< the previous time of day's whole seconds, s */
    int has_previous;
} nte_clock_column_t;

/** 1 and *out when the stripped cell s[0..n) is written as a clock or a date and time, with
 *  an hour, minute, second, day and zone that exist; 0 otherwise (clock_time.read_stamp). */
int nte_clock_read_stamp(const char* s, size_t n, int decimal_comma, nte_stamp_t* out);

/** The stamp's seconds, s: the whole (a time of day's days added) plus the fraction
 *  (clock_time.ClockColumn.seconds). */
double nte_clock_seconds(nte_clock_column_t* column, const nte_stamp_t* stamp);

#endif /* NTE_CLOCK_TIME_H */
