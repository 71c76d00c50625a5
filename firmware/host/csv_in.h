/*
 * Strict reader of insertion CSV files for the host programs (the C twin of
 * reference_py/tools/csvio.py read_trial, with the rules of its docstring and the csv module's
 * excel dialect: UTF-8 with or without a BOM, '#' comments, blank lines and rows of empty cells
 * skipped, quoted cells, "" inside quotes, a quoted cell across lines; ',' ';' or a tab
 * between cells as the header's first line shows, or runs of spaces where it holds none of
 * them (numpy.savetxt's default), a decimal comma where it is not ','; a row whose depth, force
 * or given velocity is missing left out, and one whose time repeats the previous sample's; a
 * preamble before the header skipped, a header in a leading comment where no other line holds
 * the names (numpy.savetxt's "# t_s depth_mm force_n"), no header where every name read is a
 * column's position (--columns t=1,depth=2,force=3), a units row after the header kept
 * (units_row.h), a time written as a clock read in seconds (clock_time.h); the columns not
 * read -- all but the time, depth, force, velocity and NTE_CSV_TRUTH_COLUMN -- not looked at,
 * and a row with nothing in the columns read skipped; the same refusals word for word).  The
 * rules' constants are generated from the Python reader into nte_units.h.  Host only: uses
 * malloc and double.
 */
#ifndef NTE_CSV_IN_H
#define NTE_CSV_IN_H

#include "name_value.h"
#include "nte.h"
#include "nte_units.h"

#include <stddef.h>

typedef struct nte_trial_t {
    size_t n;
    double* t_s;
    double* depth_mm;
    double* velocity_mm_s;
    double* force_n;
    size_t* line; /**< the physical line of every sample (1-based) */
    int velocity_given;
    /** Rows left out for a missing depth, force or given velocity (a dropout: an empty cell,
     *  nan or NA; csvio.read_table skip_missing): how many, and the first lines of them. */
    size_t left_out;
    size_t left_out_line[NTE_CSV_LEFT_OUT_LISTED];
    /** Rows left out because their time equals the previous sample's (a repeat; the library
     *  rejects a sample not later than the last; csvio.read_table repeat_left_out): how many,
     *  and the first lines of them.  A time that goes back is refused. */
    size_t repeated;
    size_t repeated_line[NTE_CSV_LEFT_OUT_LISTED];
    /** 1: the time column is written as clock times (a time of day, or a date and time:
     *  clock_time.h), read in seconds; a time unit other than s is then refused. */
    int clock;
    /** A units row under the header (units_row.h): its line (0: none) and the time's, depth's
     *  and force's cells, stripped (NULL where empty), which nte_units_row_check holds to the
     *  units they are read in. */
    size_t units_row_line;
    char* units_row[3];
} nte_trial_t;

/** Which of the file's columns hold the time, depth, force and velocity (csvio.ColumnMap;
 *  column_map.h parses --columns into one). */
#define NTE_COLUMN_NAME_MAX 256U
typedef struct nte_columns_t {
    char t[NTE_COLUMN_NAME_MAX];
    char depth[NTE_COLUMN_NAME_MAX];
    char force[NTE_COLUMN_NAME_MAX];
    char velocity[NTE_COLUMN_NAME_MAX]; /**< read when the file has it; "": never read */
    int velocity_required;              /**< 1: refused when the file lacks it */
    int mapped;        /**< 1: given by --columns (a missing column then gets no unit advice) */
    int force_ignored; /**< 1: --predict-only: the force column may be absent and a missing
                        *   force keeps its row (such a force is NaN); csvio.read_trial's
                        *   force_ignored.  Set after nte_column_map_parse. */
} nte_columns_t;

/** The standard names: t_s, depth_mm, force_n, and velocity_mm_s when the file has it. */
void nte_columns_standard(nte_columns_t* columns);

/** How a file's columns are converted to N, s and mm (csvio.Units): the factor of each unit
 *  (nte_units.h), the sign conventions (depth grows into the tissue, force is positive while
 *  inserting) and whether the result is checked (units_check.h). */
typedef struct nte_units_t {
    const char* force; /**< the unit names (for the messages), e.g. "mN" */
    const char* time;
    const char* depth;
    double force_factor; /**< to N */
    double time_factor;  /**< to s */
    double depth_factor; /**< to mm */
    int force_sign;      /**< +1 or -1 */
    int depth_sign;
    double depth_offset_mm; /**< added to the depth after its factor and sign, mm */
    int check;              /**< 0: --no-units-check */
    nte_columns_t columns;  /**< which columns are read (the messages name them so) */
} nte_units_t;

/** Read `path`'s standard columns.  On error returns -1 and writes "FILE:LINE: ..." (no
 *  newline) to err. */
int nte_trial_read(const char* path, nte_trial_t* trial, char* err, size_t err_size);
/** The same, reading the columns `columns` names (the messages name them so). */
int nte_trial_read_columns(const char* path, const nte_columns_t* columns, nte_trial_t* trial,
                           char* err, size_t err_size);
void nte_trial_free(nte_trial_t* trial);
/** The note a host program writes to stderr when rows were left out (csvio.left_out_note,
 *  word for word; "" when none was): a line for the dropouts (the file, how many rows, which
 *  columns, the first lines) and one for the repeated times, joined by a newline. */
void nte_trial_left_out_note(const char* path, const nte_trial_t* trial,
                             const nte_columns_t* columns, char* out, size_t out_size);
/** Convert the columns from the file's units and signs to N, s, mm (csvio.read_trial with
 *  units): time by its factor, depth and force by factor and sign, a given velocity by depth
 *  factor and sign / time factor, else central differences of the converted depth. */
void nte_trial_convert(nte_trial_t* trial, const nte_units_t* units);
/** Sample k of the trial as the library takes it: time in integer microseconds,
 * floor(t * 1e6 + 0.5) (csvio.time_us), depth and velocity rounded to nte_real_t, the force
 * too, or 0 when `force_ignored` (--predict-only: the bank is fed 0 N, never rejected). */
void nte_trial_sample(const nte_trial_t* tr, size_t k, int force_ignored, nte_sample_t* s);
/** Central differences in double, one-sided at the ends (csvio.central_difference). */
void nte_central_difference(const double* t, const double* x, size_t n, double* v);
#endif /* NTE_CSV_IN_H */
