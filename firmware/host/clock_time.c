/* A time column written as a clock or a calendar: the twin of reference_py/tools/clock_time.py
 * (clock_time.h). */
#include "clock_time.h"

#include <stdlib.h>
#include <string.h>

#define SECONDS_PER_DAY 86400
/* a time of day this far before the previous one is the next day's (clock_time.ROLLOVER_S) */
#define ROLLOVER_S 43200

/* k decimal digits at s[*i], as a value; -1 when fewer (the position then undefined) */
static int64_t digits(const char* s, const size_t n, size_t* i, const size_t k)
{
    int64_t v = 0;
    for (size_t j = 0U; j < k; j++) {
        if ((*i >= n) || (s[*i] < '0') || (s[*i] > '9')) {
            return -1;
        }
        v = (v * 10) + (int64_t)(s[*i] - '0');
        (*i)++;
    }
    return v;
}

static int is_digit(const char c) { return (c >= '0') && (c <= '9'); }

static int is_leap(const int64_t y) { return ((y % 4 == 0) && (y % 100 != 0)) || (y % 400 == 0); }

/* The days from 1970-01-01 to the day y-m-d of the proleptic Gregorian calendar (what
 * Python's date.toordinal() differences give): the year taken to start in March, so that
 * the leap day ends it; 400-year eras of 146 097 days; a month's first day from March on at
 * (153 m' + 2) / 5, m' counting from March. */
static int64_t days_since_1970(int64_t y, const int64_t m, const int64_t d)
{
    y -= (m <= 2) ? 1 : 0;
    const int64_t era = ((y >= 0) ? y : (y - 399)) / 400;
    const int64_t year_of_era = y - (era * 400);
    const int64_t month_from_march = (m > 2) ? (m - 3) : (m + 9);
    const int64_t day_of_year = (((153 * month_from_march) + 2) / 5) + d - 1;
    const int64_t day_of_era = (year_of_era * 365) + (year_of_era / 4) - (year_of_era / 100) +
                               day_of_year;
    return (era * 146097) + day_of_era - 719468;
}

/* A date YYYY-MM-DD or YYYY/MM/DD followed by 'T' or a space, at s[*i]: 1 and its day; 0 when
 * the cell does not start so; -1 when it does but no such day exists (Python's date range:
 * years 1 to 9999). */
static int read_date(const char* s, const size_t n, size_t* i, int64_t* day)
{
    if ((n < 11U) || !is_digit(s[0]) || !is_digit(s[1]) || !is_digit(s[2]) || !is_digit(s[3]) ||
        ((s[4] != '-') && (s[4] != '/'))) {
        return 0;
    }
    size_t j = 0U;
    const int64_t y = digits(s, n, &j, 4U);
    const char sep = s[j++];
    const int64_t m = digits(s, n, &j, 2U);
    if ((m < 0) || (j >= n) || (s[j++] != sep)) {
        return 0;
    }
    const int64_t d = digits(s, n, &j, 2U);
    if ((d < 0) || (j >= n) || ((s[j] != 'T') && (s[j] != ' '))) {
        return 0;
    }
    *i = j + 1U;
    static const int64_t month_days[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    if ((y < 1) || (m < 1) || (m > 12) || (d < 1) ||
        (d > month_days[m - 1] + (((m == 2) && is_leap(y)) ? 1 : 0))) {
        return -1;
    }
    *day = days_since_1970(y, m, d);
    return 1;
}

/* A zone at s[i..n): Z, +HH:MM, +HHMM, -HH:MM or -HHMM; 1 and its offset east of UTC, s */
static int read_zone(const char* s, const size_t n, size_t i, int64_t* offset)
{
    if ((i + 1U == n) && (s[i] == 'Z')) {
        *offset = 0;
        return 1;
    }
    if ((s[i] != '+') && (s[i] != '-')) {
        return 0;
    }
    const int64_t sign = (s[i] == '+') ? 1 : -1;
    i++;
    const int64_t h = digits(s, n, &i, 2U);
    if ((i < n) && (s[i] == ':')) {
        i++;
    }
    const int64_t m = digits(s, n, &i, 2U);
    if ((h < 0) || (m < 0) || (i != n) || (h > 23) || (m > 59)) {
        return 0;
    }
    *offset = sign * ((h * 3600) + (m * 60));
    return 1;
}

int nte_clock_read_stamp(const char* s, const size_t n, const int decimal_comma, nte_stamp_t* out)
{
    size_t i = 0U;
    int64_t day = 0;
    const int dated = read_date(s, n, &i, &day);
    if (dated < 0) {
        return 0;
    }
    /* the hour: one or two digits */
    const size_t hour_digits = ((i + 1U < n) && is_digit(s[i + 1U])) ? 2U : 1U;
    const int64_t h = digits(s, n, &i, hour_digits);
    if ((h < 0) || (i >= n) || (s[i++] != ':')) {
        return 0;
    }
    const int64_t mi = digits(s, n, &i, 2U);
    if ((mi < 0) || (i >= n) || (s[i++] != ':')) {
        return 0;
    }
    const int64_t sec = digits(s, n, &i, 2U);
    if (sec < 0) {
        return 0;
    }
    size_t k = 0U;
    if ((i < n) && ((s[i] == '.') || ((decimal_comma != 0) && (s[i] == ',')))) {
        i++;
        while ((i < n) && is_digit(s[i]) && (k < NTE_CLOCK_FRACTION_DIGITS_MAX)) {
            out->fraction[k++] = s[i++];
        }
        if ((k == 0U) || ((i < n) && is_digit(s[i]))) {
            return 0; /* a mark without digits, or more digits than a fraction may have */
        }
    }
    out->fraction[k] = '\0';
    int64_t offset = 0;
    if ((i < n) && ((dated == 0) || (read_zone(s, n, i, &offset) == 0))) {
        return 0; /* a zone belongs to a date's time only */
    }
    if ((h > 23) || (mi > 59) || (sec > 59)) {
        return 0;
    }
    out->dated = dated;
    out->whole = (h * 3600) + (mi * 60) + sec - offset + (day * SECONDS_PER_DAY);
    return 1;
}

double nte_clock_seconds(nte_clock_column_t* column, const nte_stamp_t* stamp)
{
    int64_t whole = stamp->whole;
    if (stamp->dated == 0) {
        if ((column->has_previous != 0) && (whole < column->previous - ROLLOVER_S)) {
            column->days++;
        }
        column->previous = whole;
        column->has_previous = 1;
        whole += column->days * SECONDS_PER_DAY;
    }
    double fraction = 0.0;
    if (stamp->fraction[0] != '\0') {
        char text[NTE_CLOCK_FRACTION_DIGITS_MAX + 3U] = "0.";
        (void)memcpy(text + 2, stamp->fraction, strlen(stamp->fraction) + 1U);
        fraction = strtod(text, NULL);
    }
    return (double)whole + fraction;
}
