/* The plausibility check of an insertion's units and signs; mirrors
 * reference_py/tools/units_check.py check_units (its numbers formatted as Python formats them:
 * "{x:.4g}" and "{x:g}" are C's %.4g and %g, a share "{100 x:.0f} %" is %.0f). */
#include "units_check.h"

#include "nte_units.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int ascending(const void* a, const void* b)
{
    const double x = *(const double*)a;
    const double y = *(const double*)b;
    return (x < y) ? -1 : ((x > y) ? 1 : 0);
}

/* np.median of n > 0 values (sorted in place): the middle one, or the mean of the two. */
static double median(double* v, const size_t n)
{
    qsort(v, n, sizeof *v, ascending);
    const size_t h = n / 2U;
    return ((n % 2U) != 0U) ? v[h] : ((v[h - 1U] + v[h]) / 2.0);
}

/* A sample taken while the stage moves either way (the direction of the insertion is judged on
 * those): a force, the speed above the inserting one. */
static int is_moving(const nte_trial_t* tr, const size_t k)
{
    return isfinite(tr->force_n[k]) &&
           (fabs(tr->velocity_mm_s[k]) > NTE_UNITS_INSERTING_SPEED_MM_S);
}

/* np.mean of a boolean array: the share of true. */
static double share(const size_t count, const size_t n) { return (double)count / (double)n; }

/* The tare: the median of the first TARE_SAMPLES forces (a record as measured starts in the
 * air), 0 without any.  v: n scratch values. */
static double tare_of(const nte_trial_t* tr, double* v)
{
    size_t m = 0U;
    for (size_t k = 0U; (k < tr->n) && (m < NTE_UNITS_TARE_SAMPLES); k++) {
        if (isfinite(tr->force_n[k])) {
            v[m++] = tr->force_n[k];
        }
    }
    return (m > 0U) ? median(v, m) : 0.0;
}

/* units_check._air_tare: the force in the air, which the force's sign is judged from -- the tare of
 * the first forces, unless the record ends more than MIN_STROKE_MM shallower than it starts
 * (the medians of the first and last TARE_SAMPLES depths): a logger started, or a node
 * restarted, with the needle in the tissue, whose last forces' median is the air's.
 * v: n scratch values. */
static double air_tare(const nte_trial_t* tr, const double tare, double* v)
{
    size_t m = 0U;
    for (size_t k = 0U; (k < tr->n) && (m < NTE_UNITS_TARE_SAMPLES); k++) {
        v[m++] = tr->depth_mm[k];
    }
    const double start = median(v, m);
    m = 0U;
    for (size_t k = tr->n; (k > 0U) && (m < NTE_UNITS_TARE_SAMPLES); k--) {
        v[m++] = tr->depth_mm[k - 1U];
    }
    const double end = median(v, m);
    if (!(end < (start - NTE_UNITS_MIN_STROKE_MM))) {
        return tare;
    }
    m = 0U;
    for (size_t k = tr->n; (k > 0U) && (m < NTE_UNITS_TARE_SAMPLES); k--) {
        if (isfinite(tr->force_n[k - 1U])) {
            v[m++] = tr->force_n[k - 1U];
        }
    }
    return median(v, m);
}

/* A sample taken while inserting, the depth read `way` (+1 as it is, -1 the other way): a
 * force, the stage moving in, the depth beyond 0. */
static int is_inserting(const nte_trial_t* tr, const size_t k, const double way)
{
    return isfinite(tr->force_n[k]) &&
           ((way * tr->velocity_mm_s[k]) > NTE_UNITS_INSERTING_SPEED_MM_S) &&
           ((way * tr->depth_mm[k]) > 0.0);
}

/* units_check._negative_while_inserting: the force less its tare, judged on the samples taken while
 * inserting (a force, the stage moving in, the depth beyond 0) that depart from the tare by
 * more than SIGN_DEPART_SHARE of the largest departure there -- their median negative is the
 * sensor's opposite sign.  `way` -1 reads the depth (and
 * so the velocity) the other way.  Returns 1 and the share of negative forces, or 0 when the
 * median is not negative or too few samples say.  v: n scratch values. */
static int negative_while_inserting(const nte_trial_t* tr, const double tare, const double way,
                                    double* v, double* negative_share)
{
    size_t inserting = 0U;
    double top = 0.0;
    for (size_t k = 0U; k < tr->n; k++) {
        if (is_inserting(tr, k, way)) {
            inserting++;
            const double dev = fabs(tr->force_n[k] - tare);
            top = (dev > top) ? dev : top;
        }
    }
    if (inserting < NTE_UNITS_INSERTING_MIN_SAMPLES) {
        return 0;
    }
    size_t m = 0U;
    size_t negative = 0U;
    for (size_t k = 0U; k < tr->n; k++) {
        const double rel = tr->force_n[k] - tare;
        if (is_inserting(tr, k, way) && (fabs(rel) > (NTE_UNITS_SIGN_DEPART_SHARE * top))) {
            v[m++] = rel;
            negative += (rel < 0.0) ? 1U : 0U;
        }
    }
    if ((m < NTE_UNITS_INSERTING_MIN_SAMPLES) || (median(v, m) >= 0.0)) {
        return 0;
    }
    *negative_share = share(negative, m);
    return 1;
}

/* units_check._sign_advice: the options that turn the depth's and/or the force's sign over from the
 * reading `u` gives -- a sign not given is added, one given is dropped. */
static void sign_advice(const nte_units_t* u, const int depth, const int force, char* buf,
                        size_t cap)
{
    char add[64] = "";
    char drop[64] = "";
    if (depth) {
        (void)strncat((u->depth_sign == -1) ? drop : add, "--depth-sign -1", 31U);
    }
    if (force) {
        char* to = (u->force_sign == -1) ? drop : add;
        (void)strncat(to, (to[0] != '\0') ? " --force-sign -1" : "--force-sign -1", 31U);
    }
    if ((add[0] != '\0') && (drop[0] != '\0')) {
        (void)snprintf(buf, cap, "convert with %s and read it without %s", add, drop);
    } else if (add[0] != '\0') {
        (void)snprintf(buf, cap, "convert with %s", add);
    } else {
        (void)snprintf(buf, cap, "read it without %s", drop);
    }
}

static double unit_factor(const nte_unit_t* units, const size_t n, const char* name)
{
    for (size_t i = 0U; i < n; i++) {
        if (strcmp(units[i].name, name) == 0) {
            return units[i].factor;
        }
    }
    return (double)NAN;
}

static double force_unit(const char* name)
{
    static const nte_unit_t units[NTE_FORCE_UNIT_COUNT] = NTE_FORCE_UNITS;
    return unit_factor(units, NTE_FORCE_UNIT_COUNT, name);
}

static double depth_unit(const char* name)
{
    static const nte_unit_t units[NTE_DEPTH_UNIT_COUNT] = NTE_DEPTH_UNITS;
    return unit_factor(units, NTE_DEPTH_UNIT_COUNT, name);
}

/* Why a median time step of dt s, read in `unit`, is too long (units_check._time_hint): the first
 * smaller unit of the table that makes it fit the gap limit, or too coarse (always for a clock:
 * its time is in seconds by its writing). */
static void time_hint(double dt, const char* unit, double dt_max, int clock, char* buf, size_t cap)
{
    static const nte_unit_t units[NTE_TIME_UNIT_COUNT] = NTE_TIME_UNITS;
    static const char* const words[NTE_TIME_UNIT_COUNT] = NTE_TIME_UNIT_WORDS;
    size_t i = 0U;
    while ((i < NTE_TIME_UNIT_COUNT) && (strcmp(units[i].name, unit) != 0)) {
        i++;
    }
    if (clock != 0) {
        i = NTE_TIME_UNIT_COUNT;
    }
    for (size_t j = i + 1U; j < NTE_TIME_UNIT_COUNT; j++) {
        if (((dt * units[j].factor) / units[i].factor) <= dt_max) {
            (void)snprintf(buf, cap, "probably %s: convert with --time-unit %s", words[j],
                           units[j].name);
            return;
        }
    }
    (void)snprintf(buf, cap, "too coarse for the estimator");
}

/* units_check._first_departures: the first INSERTING_MIN_SAMPLES samples taken while the stage
 * moves (either way) where the force departs from its tare by more than SIGN_DEPART_SHARE of its
 * largest departure while moving.  Writes their indices to first[] (room for
 * INSERTING_MIN_SAMPLES) and that departure to *top; returns how many (fewer when too few
 * samples move or depart). */
static size_t first_departures(const nte_trial_t* tr, const double tare, size_t* first, double* top)
{
    size_t moving = 0U;
    *top = 0.0;
    for (size_t k = 0U; k < tr->n; k++) {
        if (is_moving(tr, k)) {
            moving++;
            const double dev = fabs(tr->force_n[k] - tare);
            *top = (dev > *top) ? dev : *top;
        }
    }
    if (moving < NTE_UNITS_INSERTING_MIN_SAMPLES) {
        return 0U;
    }
    size_t seen = 0U;
    for (size_t k = 0U; (k < tr->n) && (seen < NTE_UNITS_INSERTING_MIN_SAMPLES); k++) {
        if (is_moving(tr, k) &&
            (fabs(tr->force_n[k] - tare) > (NTE_UNITS_SIGN_DEPART_SHARE * *top))) {
            first[seen++] = k;
        }
    }
    return seen;
}

/* units_check._offset_advice: the --depth-offset that makes the needle start at 0 mm (d0: its first
 * depth as read with the offset given), or, beyond its range, what to do instead; with
 * `force`, the force's sign turned over too. */
static void offset_advice(const nte_units_t* u, const double d0, const int force, char* buf,
                          size_t cap)
{
    const double offset = u->depth_offset_mm - d0;
    if (fabs(offset) > NTE_UNITS_DEPTH_OFFSET_MAX_MM) {
        char also[96] = "";
        if (force) {
            char advice[80];
            sign_advice(u, 0, 1, advice, sizeof advice);
            (void)snprintf(also, sizeof also, " and %s", advice);
        }
        (void)snprintf(buf, cap, "subtract its start so the needle starts at 0 mm or above%s",
                       also);
        return;
    }
    const int drop = force && (u->force_sign == -1);
    (void)snprintf(buf, cap,
                   "convert with --depth-offset %.6g%s%s (the needle then starts at 0 mm)", offset,
                   (force && !drop) ? " --force-sign -1" : "",
                   drop ? " and read it without --force-sign -1" : "");
}

/* Rule 1: time steps of seconds (ms or us read as s).  v: n - 1 scratch values. */
static int check_time(const char* path, const nte_trial_t* tr, const nte_units_t* u,
                      const nte_limits_t* lim, double* v, char* err, size_t es)
{
    if (tr->n < 2U) {
        return 0;
    }
    for (size_t k = 0U; (k + 1U) < tr->n; k++) {
        v[k] = tr->t_s[k + 1U] - tr->t_s[k];
    }
    const double dt = median(v, tr->n - 1U);
    if (dt > lim->dt_max_s) {
        char hint[128];
        time_hint(dt, u->time, lim->dt_max_s, tr->clock, hint, sizeof hint);
        (void)snprintf(err, es,
                       "%s: column '%s': median time step %.4g s (longer than the %g "
                       "s gap limit): %s",
                       path, u->columns.t, dt, lim->dt_max_s, hint);
        return -1;
    }
    return 0;
}

/* units_check._stroke_hint: a stroke under NTE_UNITS_MIN_STROKE_MM at `speed` (mm/s) read as mm is
 * named in each unit of NTE_UNITS_SHORT_STROKE_UNITS that makes it MIN_STROKE_MM..STROKE_MAX_MM
 * or, if none does, that makes its speed SLOW_SPEED_MM_S or more. */
static void stroke_hint(const double stroke, const double speed, const nte_units_t* u, char* out,
                        const size_t cap)
{
    static const char* const units[NTE_UNITS_SHORT_STROKE_COUNT][2] = NTE_UNITS_SHORT_STROKE_UNITS;
    size_t named[NTE_UNITS_SHORT_STROKE_COUNT];
    size_t n = 0U;
    /* a needle's stroke in the unit; if no unit gives one, a shallow one at a needle's speed */
    for (int by_speed = 0; (by_speed < 2) && (n == 0U); by_speed++) {
        for (size_t i = 0U; i < NTE_UNITS_SHORT_STROKE_COUNT; i++) {
            const double k = depth_unit(units[i][0]);
            const int fits = (by_speed != 0) ? ((speed * k) >= NTE_UNITS_SLOW_SPEED_MM_S)
                                             : (((stroke * k) >= NTE_UNITS_MIN_STROKE_MM) &&
                                                ((stroke * k) <= NTE_UNITS_STROKE_MAX_MM));
            if (fits != 0) {
                named[n++] = i;
            }
        }
    }
    if ((strcmp(u->depth, "mm") != 0) || (n == 0U)) {
        (void)snprintf(out, cap, "no insertion");
        return;
    }
    /* "probably A: ...", "probably A or B: ...", "probably A, B or C: ..." */
    int o = snprintf(out, cap, "probably ");
    for (size_t i = 0U; (i < n) && (o >= 0) && ((size_t)o < cap); i++) {
        const char* sep = (i == 0U) ? "" : ((i + 1U == n) ? " or " : ", ");
        o += snprintf(out + o, cap - (size_t)o, "%s%s", sep, units[named[i]][1]);
    }
    for (size_t i = 0U; (i < n) && (o >= 0) && ((size_t)o < cap); i++) {
        o += snprintf(out + o, cap - (size_t)o, "%s--depth-unit %s",
                      (i == 0U) ? ": convert with " : " or ", units[named[i]][0]);
    }
}

/* units_check.ramp_speed: how fast the depth moves (mm/s, as read): RAMP_TO - RAMP_FROM of its
 * largest distance from the first sample over the time from first reaching RAMP_FROM of it to
 * first reaching RAMP_TO; HUGE_VAL when one sample does it, 0 when the depth never moves. */
static double ramp_speed(const nte_trial_t* tr)
{
    const double d0 = tr->depth_mm[0];
    double reach = 0.0;
    for (size_t k = 0U; k < tr->n; k++) {
        const double away = fabs(tr->depth_mm[k] - d0);
        reach = (away > reach) ? away : reach;
    }
    if (!(reach > 0.0)) {
        return 0.0;
    }
    size_t k_from = tr->n;
    size_t k_to = tr->n;
    for (size_t k = 0U; (k < tr->n) && (k_to == tr->n); k++) {
        const double away = fabs(tr->depth_mm[k] - d0);
        k_from = ((k_from == tr->n) && (away >= (NTE_UNITS_RAMP_FROM * reach))) ? k : k_from;
        k_to = (away >= (NTE_UNITS_RAMP_TO * reach)) ? k : k_to;
    }
    if (k_to <= k_from) {
        return HUGE_VAL;
    }
    return ((NTE_UNITS_RAMP_TO - NTE_UNITS_RAMP_FROM) * reach) / (tr->t_s[k_to] - tr->t_s[k_from]);
}

/* Micrometres read as mm: most depths outside the accepted range, every one inside it and the
 * stroke still a millimetre at a thousandth of the value. */
static int in_micrometres(const nte_trial_t* tr, const nte_units_t* u, const nte_limits_t* lim,
                          const double stroke, double* far)
{
    const double um = depth_unit("um");
    size_t out = 0U;
    int inside = 1;
    for (size_t k = 0U; k < tr->n; k++) {
        const double d = tr->depth_mm[k];
        out += ((d < lim->depth_min_mm) || (d > lim->depth_max_mm)) ? 1U : 0U;
        inside &= ((d * um) >= lim->depth_min_mm) && ((d * um) <= lim->depth_max_mm);
    }
    *far = share(out, tr->n);
    return (*far > NTE_UNITS_MAX_REJECTED_SHARE) && (strcmp(u->depth, "mm") == 0) &&
           ((stroke * um) >= NTE_UNITS_MIN_STROKE_MM) && inside;
}

/* Rules 2 and 3: a stroke under a millimetre (metres read as mm), depths in micrometres,
 * mostly negative depths -- with the force too when, read that way, it would be negative
 * while inserting (one message, not two in turn).  v: n scratch values. */
static int check_depth(const char* path, const nte_trial_t* tr, const nte_units_t* u,
                       const nte_limits_t* lim, const double tare, double* v, char* err, size_t es)
{
    double lo = tr->depth_mm[0];
    double hi = tr->depth_mm[0];
    size_t neg = 0U;
    for (size_t k = 0U; k < tr->n; k++) {
        const double d = tr->depth_mm[k];
        lo = (d < lo) ? d : lo;
        hi = (d > hi) ? d : hi;
        neg += (d < 0.0) ? 1U : 0U;
    }
    const double stroke = hi - lo;
    /* a depth that never moves, or a shallow one at a needle's speed, is no unit question */
    const double speed = ((0.0 < stroke) && (stroke < NTE_UNITS_MIN_STROKE_MM)) ? ramp_speed(tr)
                                                                                : HUGE_VAL;
    if (speed < NTE_UNITS_SLOW_SPEED_MM_S) {
        char hint[256];
        stroke_hint(stroke, speed, u, hint, sizeof hint);
        (void)snprintf(err, es,
                       "%s: column '%s': the depth spans only %.4g mm at %.2g mm/s (less than "
                       "%g mm, slower than %g mm/s): %s",
                       path, u->columns.depth, stroke, speed, NTE_UNITS_MIN_STROKE_MM,
                       NTE_UNITS_SLOW_SPEED_MM_S, hint);
        return -1;
    }
    double far = 0.0;
    if (in_micrometres(tr, u, lim, stroke, &far)) {
        (void)snprintf(err, es,
                       "%s: column '%s': %.0f %% of the depths are outside the accepted range "
                       "%g..%g mm (from %.4g to %.4g): probably micrometres: convert with "
                       "--depth-unit um",
                       path, u->columns.depth, 100.0 * far, lim->depth_min_mm, lim->depth_max_mm,
                       lo, hi);
        return -1;
    }
    const double ns = share(neg, tr->n);
    char advice[160];
    if ((ns > NTE_UNITS_NEGATIVE_DEPTH_SHARE) && (u->depth_sign == 1)) {
        /* the force first departs while the depth grows: the direction is right, the origin
         * is not (a stage counting up from before the needle's start) -- and the force's sign
         * too if it first falls */
        size_t first[NTE_UNITS_INSERTING_MIN_SAMPLES];
        double top = 0.0;
        const size_t seen = first_departures(tr, tare, first, &top);
        size_t grows = 0U;
        size_t falls = 0U;
        for (size_t i = 0U; i < seen; i++) {
            const size_t k = first[i];
            grows += (tr->velocity_mm_s[k] > 0.0) ? 1U : 0U;
            falls += ((tr->velocity_mm_s[k] > 0.0) && ((tr->force_n[k] - tare) < 0.0)) ? 1U : 0U;
        }
        if ((seen == NTE_UNITS_INSERTING_MIN_SAMPLES) && ((2U * grows) > seen)) {
            const int force_too = (2U * falls) > seen;
            offset_advice(u, tr->depth_mm[0], force_too, advice, sizeof advice);
            (void)snprintf(err, es,
                           "%s: column '%s': %.0f %% of the depths are negative (down to "
                           "%.4g mm) although the depth grows where the force first %s from its "
                           "tare: the stage counts from an origin before the needle's start%s: %s",
                           path, u->columns.depth, 100.0 * ns, lo, force_too ? "falls" : "rises",
                           force_too ? ", and the force is measured the other way" : "", advice);
            return -1;
        }
    }
    if ((ns > NTE_UNITS_NEGATIVE_DEPTH_SHARE) && (u->depth_sign == 1)) {
        double both = 0.0;
        const int force_too = negative_while_inserting(tr, tare, -1.0, v, &both);
        char also[160] = "";
        if (force_too) {
            (void)snprintf(also, sizeof also,
                           ", and the force with it (read that way, the force less its tare "
                           "is negative in %.0f %% of the samples taken while inserting)",
                           100.0 * both);
        }
        sign_advice(u, 1, force_too, advice, sizeof advice);
        (void)snprintf(err, es,
                       "%s: column '%s': %.0f %% of the depths are negative (down to "
                       "%.4g mm): probably measured the other way%s: %s",
                       path, u->columns.depth, 100.0 * ns, lo, also, advice);
        return -1;
    }
    if (ns > NTE_UNITS_NEGATIVE_DEPTH_SHARE) {
        /* the sign was given: a stage that counts down to the tissue from a positive origin */
        offset_advice(u, tr->depth_mm[0], 0, advice, sizeof advice);
        (void)snprintf(err, es,
                       "%s: column '%s': %.0f %% of the depths are negative with --depth-sign -1 "
                       "(down to %.4g mm): the stage counts from an origin beyond the tissue: %s",
                       path, u->columns.depth, 100.0 * ns, lo, advice);
        return -1;
    }
    return 0;
}

/* Rule 5b (units_check._check_direction): a depth that runs the other way although its values are
 * positive (a stage counting down towards the tissue).  The needle loads the force as it goes
 * in, so where the force first leaves its tare while the stage moves, the depth must grow: of
 * the first INSERTING_MIN_SAMPLES moving samples that depart by more than SIGN_DEPART_SHARE of
 * the largest departure, more than half rising while the depth falls is refused -- in a record
 * that starts and ends in the air (its last TARE_SAMPLES forces back at the tare: one that
 * starts in the tissue never comes back to its first "tare") and departs by more than
 * DEPARTURE_MADS median absolute deviations of the tare's samples (not the air alone).
 * v: n scratch values. */
static int check_direction(const char* path, const nte_trial_t* tr, const nte_units_t* u,
                           const double tare, double* v, char* err, size_t es)
{
    size_t firsts[NTE_UNITS_INSERTING_MIN_SAMPLES];
    double top = 0.0;
    const size_t seen = first_departures(tr, tare, firsts, &top);
    if (seen < NTE_UNITS_INSERTING_MIN_SAMPLES) {
        return 0;
    }
    const size_t first = firsts[0];
    size_t against = 0U;
    for (size_t i = 0U; i < seen; i++) {
        const size_t k = firsts[i];
        against += ((tr->velocity_mm_s[k] < 0.0) && ((tr->force_n[k] - tare) > 0.0)) ? 1U : 0U;
    }
    /* the median of the last TARE_SAMPLES forces, and the tare's median absolute deviation */
    size_t m = 0U;
    for (size_t k = tr->n; (k > 0U) && (m < NTE_UNITS_TARE_SAMPLES); k--) {
        if (isfinite(tr->force_n[k - 1U])) {
            v[m++] = tr->force_n[k - 1U];
        }
    }
    const double end = median(v, m);
    m = 0U;
    for (size_t k = 0U; (k < tr->n) && (m < NTE_UNITS_TARE_SAMPLES); k++) {
        if (isfinite(tr->force_n[k])) {
            v[m++] = fabs(tr->force_n[k] - tare);
        }
    }
    const double mad = median(v, m);
    const int in_air = fabs(end - tare) <= (NTE_UNITS_SIGN_DEPART_SHARE * top);
    if (!((top > (NTE_UNITS_DEPARTURE_MADS * mad)) && in_air)) {
        return 0;
    }
    char advice[96];
    if ((2U * against) > seen) {
        sign_advice(u, 1, 0, advice, sizeof advice);
        (void)snprintf(err, es,
                       "%s: column '%s': the force first rises from its tare while the depth "
                       "decreases (from %.4g s, at %.4g mm): a needle goes in towards larger "
                       "depths: probably measured the other way: %s",
                       path, u->columns.depth, tr->t_s[first], tr->depth_mm[first], advice);
        return -1;
    }
    /* The same stage with the sensor inverted too: the force first *falls* while the depth
     * decreases (of the first INSERTING_MIN_SAMPLES samples that depart, moving or not), and
     * last departs while the depth grows (the needle leaving).  A correct record read from its
     * reversal on also first falls while the depth decreases, but it leaves the tissue the same
     * way: its last departures are still taken while the depth decreases. */
    size_t early = 0U;
    size_t falling = 0U;
    size_t k0 = 0U;
    for (size_t k = 0U; (k < tr->n) && (early < NTE_UNITS_INSERTING_MIN_SAMPLES); k++) {
        const double rel = tr->force_n[k] - tare;
        if (isfinite(tr->force_n[k]) && (fabs(rel) > (NTE_UNITS_SIGN_DEPART_SHARE * top))) {
            k0 = (early == 0U) ? k : k0;
            early++;
            falling += ((tr->velocity_mm_s[k] < 0.0) && (rel < 0.0)) ? 1U : 0U;
        }
    }
    size_t late = 0U;
    size_t leaving = 0U;
    for (size_t k = tr->n; (k > 0U) && (late < NTE_UNITS_INSERTING_MIN_SAMPLES); k--) {
        const double rel = tr->force_n[k - 1U] - tare;
        if (isfinite(tr->force_n[k - 1U]) && (fabs(rel) > (NTE_UNITS_SIGN_DEPART_SHARE * top))) {
            late++;
            leaving += (tr->velocity_mm_s[k - 1U] > 0.0) ? 1U : 0U;
        }
    }
    if (((2U * falling) > early) && ((2U * leaving) > late)) {
        sign_advice(u, 1, 1, advice, sizeof advice);
        (void)snprintf(err, es,
                       "%s: column '%s': the force first falls from its tare while the depth "
                       "decreases (from %.4g s, at %.4g mm): a needle goes in towards larger "
                       "depths and pushes the force up: probably both the depth and the force "
                       "measured the other way: %s",
                       path, u->columns.depth, tr->t_s[k0], tr->depth_mm[k0], advice);
        return -1;
    }
    return 0;
}

/* Rules 4 to 6: forces mostly beyond the range (mN read as N), one force beyond a thousand
 * times the range, the force mostly negative while inserting (the sensor's other sign).
 * Between the last two, rule 5b (check_direction): the depth running the other way.
 * v: n scratch values. */
static int check_force(const char* path, const nte_trial_t* tr, const nte_units_t* u,
                       const nte_limits_t* lim, const double tare, double* v, char* err, size_t es)
{
    const double fmax = lim->force_max_n;
    size_t present = 0U;
    size_t out = 0U;
    double peak = -1.0;
    size_t kpeak = 0U;
    for (size_t k = 0U; k < tr->n; k++) {
        if (isfinite(tr->force_n[k])) {
            const double fa = fabs(tr->force_n[k]);
            present++;
            out += (fa > fmax) ? 1U : 0U;
            if (fa > peak) { /* np.argmax: the first of the largest */
                peak = fa;
                kpeak = k;
            }
        }
    }
    if (present == 0U) {
        return 0;
    }
    const double os = share(out, present);
    if (os > NTE_UNITS_MAX_FORCE_OUT_SHARE) {
        const int in_n = strcmp(u->force, "N") == 0;
        const char* hint = "not a force in N";
        if (in_n && ((peak * force_unit("gf")) <= fmax)) {
            /* a factor 9.8 apart: the values cannot tell them, the rig's manual can */
            hint = "probably millinewtons, or grams-force (a load cell read in grams): convert "
                   "with --force-unit mN or --force-unit gf";
        } else if (in_n && ((peak * force_unit("mN")) <= fmax)) {
            hint = "probably millinewtons: convert with --force-unit mN";
        } else {
            /* not a unit the reader knows */
        }
        (void)snprintf(err, es,
                       "%s: column '%s': %.0f %% of the forces exceed the configured "
                       "range \xc2\xb1%g N (up to %.4g): %s",
                       path, u->columns.force, 100.0 * os, fmax, peak, hint);
        return -1;
    }
    if (peak > (NTE_UNITS_FORCE_IMPLAUSIBLE_FACTOR * fmax)) {
        (void)snprintf(err, es,
                       "%s:%zu: column '%s': %.4g N is not a plausible force (the "
                       "configured range is \xc2\xb1%g N)",
                       path, tr->line[kpeak], u->columns.force, tr->force_n[kpeak], fmax);
        return -1;
    }
    /* judged on the force less its tare, where it departs from the tare: a record starts in
     * the air, and a negative tare over a long air gap is no sign */
    if (check_direction(path, tr, u, tare, v, err, es) != 0) {
        return -1;
    }
    const double air = air_tare(tr, tare, v);
    double negative = 0.0;
    if (negative_while_inserting(tr, air, 1.0, v, &negative)) {
        char advice[96];
        sign_advice(u, 0, 1, advice, sizeof advice);
        (void)snprintf(err, es,
                       "%s: column '%s': the force less its tare (%.4g N) is negative "
                       "in %.0f %% of the samples taken while inserting: probably the sensor's "
                       "opposite sign: %s",
                       path, u->columns.force, air, 100.0 * negative, advice);
        return -1;
    }
    return 0;
}

/* Rule 7: most samples outside the estimator's accepted ranges. */
static int check_ranges(const char* path, const nte_trial_t* tr, const nte_limits_t* lim, char* err,
                        size_t es)
{
    size_t bad = 0U;
    for (size_t k = 0U; k < tr->n; k++) {
        const double d = tr->depth_mm[k];
        const double f = tr->force_n[k];
        bad += ((d < lim->depth_min_mm) || (d > lim->depth_max_mm) ||
                (fabs(tr->velocity_mm_s[k]) > lim->speed_max_mm_s) ||
                (isfinite(f) && (fabs(f) > lim->force_max_n)))
                   ? 1U
                   : 0U;
    }
    const double bs = share(bad, tr->n);
    if (bs > NTE_UNITS_MAX_REJECTED_SHARE) {
        (void)snprintf(err, es,
                       "%s: %zu of %zu samples (%.0f %%) are outside the estimator's "
                       "accepted ranges (depth %g..%g mm, speed \xc2\xb1%g mm/s, force \xc2\xb1%g "
                       "N): check the units (--time-unit, --depth-unit, --force-unit) and signs",
                       path, bad, tr->n, 100.0 * bs, lim->depth_min_mm, lim->depth_max_mm,
                       lim->speed_max_mm_s, lim->force_max_n);
        return -1;
    }
    return 0;
}

int nte_units_check(const char* path, const nte_trial_t* tr, const nte_units_t* u,
                    const nte_limits_t* lim, char* err, size_t es)
{
    double* scratch = malloc(((tr->n > 0U) ? tr->n : 1U) * sizeof(double));
    if (scratch == NULL) {
        (void)snprintf(err, es, "%s: out of memory", path);
        return -1;
    }
    const double tare = tare_of(tr, scratch);
    const int rc = ((check_time(path, tr, u, lim, scratch, err, es) != 0) ||
                    (check_depth(path, tr, u, lim, tare, scratch, err, es) != 0) ||
                    (check_force(path, tr, u, lim, tare, scratch, err, es) != 0) ||
                    (check_ranges(path, tr, lim, err, es) != 0))
                       ? -1
                       : 0;
    free(scratch);
    return rc;
}
