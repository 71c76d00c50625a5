/* Strict CSV reader of the host programs: reference_py/tools/csvio.py read_table and read_trial
 * rule for rule and message for message, with the csv module they read with (the excel
 * dialect, as CPython 3.11's Modules/_csv.c parses it).  Python's text rules (UTF-8, str.strip,
 * repr) are name_value.h's. */
#include "csv_in.h"

#include "clock_time.h"
#include "units_row.h"

#include "name_value.h"
#include "nte_file_in.h"

#include "nte_units.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void fail(char* err, size_t size, const char* fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(err, size, fmt, ap);
    va_end(ap);
}

/* ---- the csv module's reader (excel dialect: a delimiter between cells, '"' around one) --- */

enum { start_record, start_field, in_field, in_quoted, quote_in_quoted, eat_crnl };
#define EOL 256 /* the end of a line, after its last character */
#define CSV_OUT_OF_MEMORY (-1)
#define CSV_FIELD_LIMIT (-2)
#define CSV_NEWLINE (-3)
/* csvio.BLANKS: the separator of cells cut at runs of spaces (a header line holding none of
 * ',', ';', '\t' whose names so cut are the ones read) */
#define BLANKS ' '

/* One record as it is read: the cells' bytes, each followed by '\0', and where each begins. */
typedef struct record_t {
    char* text;
    size_t len;
    size_t cap;
    size_t* start;
    size_t n;
    size_t n_cap;
    size_t field; /* where the cell being read begins in text */
    size_t chars; /* its characters so far (the module's field_len) */
    int state;
    char delimiter; /* between cells: ',', ';' or '\t' (delimiter_of) */
} record_t;

static int grow(void** p, size_t* cap, const size_t need, const size_t size)
{
    if (need <= *cap) {
        return 0;
    }
    size_t nc = (*cap == 0U) ? 64U : *cap;
    while (nc < need) {
        nc *= 2U;
    }
    void* q = realloc(*p, nc * size);
    if (q == NULL) {
        return CSV_OUT_OF_MEMORY;
    }
    *p = q;
    *cap = nc;
    return 0;
}

static int put_byte(record_t* r, const char c)
{
    if (grow((void**)&r->text, &r->cap, r->len + 1U, 1U) != 0) {
        return CSV_OUT_OF_MEMORY;
    }
    r->text[r->len++] = c;
    return 0;
}

/* parse_add_char: the limit counts characters, so a UTF-8 continuation byte is not counted */
static int add_char(record_t* r, const int c)
{
    if ((((unsigned)c) & 0xc0U) != 0x80U) {
        if (r->chars >= NTE_CSV_FIELD_LIMIT) {
            return CSV_FIELD_LIMIT;
        }
        r->chars++;
    }
    return put_byte(r, (char)c);
}

static int save_field(record_t* r)
{
    if ((put_byte(r, '\0') != 0) ||
        (grow((void**)&r->start, &r->n_cap, r->n + 1U, sizeof *r->start) != 0)) {
        return CSV_OUT_OF_MEMORY;
    }
    r->start[r->n++] = r->field;
    r->field = r->len;
    r->chars = 0U;
    return 0;
}

static void record_reset(record_t* r)
{
    r->len = 0U;
    r->n = 0U;
    r->field = 0U;
    r->chars = 0U;
    r->state = start_record;
}

/* parse_process_char: one character (a byte: the ones that matter are ASCII) or EOL. */
static int feed(record_t* r, const int c)
{
    const int newline = (c == '\n') || (c == '\r') || (c == EOL);
    int rc = 0;
    if (r->state == start_record) {
        if (c == EOL) {
            return 0; /* an empty line: the record has no cell */
        }
        if ((c == '\n') || (c == '\r')) {
            r->state = eat_crnl;
            return 0;
        }
        r->state = start_field;
    }
    switch (r->state) {
    case start_field:
        if (newline) {
            rc = save_field(r);
            r->state = (c == EOL) ? start_record : eat_crnl;
        } else if (c == '"') {
            r->state = in_quoted;
        } else if ((c == ' ') && (r->delimiter == BLANKS)) {
            /* skipinitialspace: a run of spaces is one separator */
        } else if (c == r->delimiter) {
            rc = save_field(r);
        } else {
            rc = add_char(r, c);
            r->state = in_field;
        }
        break;
    case in_field:
        if (newline) {
            rc = save_field(r);
            r->state = (c == EOL) ? start_record : eat_crnl;
        } else if (c == r->delimiter) {
            rc = save_field(r);
            r->state = start_field;
        } else {
            rc = add_char(r, c);
        }
        break;
    case in_quoted:
        if (c == '"') {
            r->state = quote_in_quoted;
        } else if (c != EOL) {
            rc = add_char(r, c); /* a line break inside quotes is the cell's */
        } else {
            /* the record goes on on the next line */
        }
        break;
    case quote_in_quoted:
        if (c == '"') {
            rc = add_char(r, c); /* "" inside quotes is one " */
            r->state = in_quoted;
        } else if (c == r->delimiter) {
            rc = save_field(r);
            r->state = start_field;
        } else if (newline) {
            rc = save_field(r);
            r->state = (c == EOL) ? start_record : eat_crnl;
        } else {
            rc = add_char(r, c); /* "a"b is ab */
            r->state = in_field;
        }
        break;
    default: /* eat_crnl */
        if (c == EOL) {
            r->state = start_record;
        } else if (!newline) {
            rc = CSV_NEWLINE;
        } else {
            /* \r\n */
        }
        break;
    }
    return rc;
}

/* ---- csvio.read_table: the header, then one sample a record ------------------------------ */

/* csvio._names: the header line line[0..n) cut at `d` (outside double quotes, the quotes
 * dropped, each name stripped), into the caller's text (n + 1 bytes), names (n + 1 pointers
 * into it, each name ended by '\0') and lengths (n + 1: a name may hold a NUL); returns how many
 * names. */
static size_t cut_names(const char* line, const size_t n, const char d, char* text, char** names,
                        size_t* lengths)
{
    size_t count = 0U;
    size_t from = 0U;
    size_t len = 0U;
    int quoted = 0;
    for (size_t i = 0U; i <= n; i++) {
        if ((i < n) && (quoted || (line[i] != d))) {
            if (line[i] == '"') {
                quoted = !quoted;
            } else {
                text[len++] = line[i];
            }
            continue;
        }
        const char* name = text + from;
        const size_t m = nte_py_strip(&name, len - from);
        names[count] = text + (name - text);
        names[count][m] = '\0';
        lengths[count] = m;
        count++;
        len++; /* the byte after the name's text (the separator's place) holds its '\0' */
        from = len;
    }
    return count;
}

/* Whether the header line cut at `d` (cut_names) has every one of the `n_want` names
 * `want`. */
static int names_hold(const char* line, const size_t n, const char d, const char* const* want,
                      const size_t n_want)
{
    char* text = malloc(n + 1U);
    char** names = malloc((n + 1U) * sizeof *names);
    size_t* lengths = malloc((n + 1U) * sizeof *lengths);
    unsigned found = 0U;
    if ((text != NULL) && (names != NULL) && (lengths != NULL)) {
        const size_t count = cut_names(line, n, d, text, names, lengths);
        for (size_t c = 0U; c < count; c++) {
            for (size_t k = 0U; k < n_want; k++) {
                if ((strlen(want[k]) == lengths[c]) &&
                    (memcmp(names[c], want[k], lengths[c]) == 0)) {
                    found |= 1U << k;
                }
            }
        }
    }
    free(text);
    free(names);
    free(lengths);
    /* out of memory: no name held, so the first separator stands */
    return found == ((1U << n_want) - 1U);
}

/* csvio.delimiter_of: the first of ',', ';', '\t' (csvio.DELIMITERS) outside double quotes in
 * the header's first line; where it holds more than one, the first under which the line's
 * names include every one of `want` (names_hold); where it holds none, BLANKS if its names cut
 * at spaces include them all, else ','. */
static const char separators[3] = {',', ';', '\t'};

/* Which of the separators (csvio.DELIMITERS, in their order) the line holds outside double
 * quotes. */
static void separators_seen(const char* line, const size_t n, int seen[3])
{
    int quoted = 0;
    seen[0] = 0;
    seen[1] = 0;
    seen[2] = 0;
    for (size_t i = 0U; i < n; i++) {
        if (line[i] == '"') {
            quoted = !quoted;
        } else if (!quoted) {
            for (size_t d = 0U; d < 3U; d++) {
                seen[d] |= (line[i] == separators[d]);
            }
        } else {
            /* a separator inside quotes is a name's */
        }
    }
}

/* csvio._holding: the first separator the line holds outside quotes under which its names
 * include every one of `want`; 0 when none does. */
static char holding(const char* line, const size_t n, const char* const* want, const size_t n_want)
{
    int seen[3];
    separators_seen(line, n, seen);
    for (size_t d = 0U; d < 3U; d++) {
        if ((seen[d] != 0) && names_hold(line, n, separators[d], want, n_want)) {
            return separators[d];
        }
    }
    if ((seen[0] + seen[1] + seen[2]) == 0) {
        return names_hold(line, n, BLANKS, want, n_want) ? BLANKS : (char)0;
    }
    return 0;
}

static char delimiter_of(const char* line, const size_t n, const char* const* want,
                         const size_t n_want)
{
    const char* const order = separators;
    int seen[3];
    separators_seen(line, n, seen);
    const int several = (seen[0] + seen[1] + seen[2]) > 1;
    for (size_t d = 0U; (d < 3U) && several && (n_want > 0U); d++) {
        if ((seen[d] != 0) && names_hold(line, n, order[d], want, n_want)) {
            return order[d];
        }
    }
    for (size_t d = 0U; d < 3U; d++) {
        if (seen[d] != 0) {
            return order[d];
        }
    }
    return ((n_want > 0U) && names_hold(line, n, BLANKS, want, n_want)) ? BLANKS : ',';
}

/* csvio._trailing_blanks_dropped: the length of line[0..n) without the spaces and tabs before
 * its line break; the break itself (the `brk` bytes from line + n - brk) is kept by the
 * caller. */
static size_t trailing_blanks(const char* line, const size_t n, size_t* brk)
{
    size_t end = n;
    while ((end > 0U) && ((line[end - 1U] == '\n') || (line[end - 1U] == '\r'))) {
        end--;
    }
    *brk = n - end;
    while ((end > 0U) && ((line[end - 1U] == ' ') || (line[end - 1U] == '\t'))) {
        end--;
    }
    return end;
}

/* csvio._NUMBER, [+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?, over the whole text; with
 * decimal_comma (a file not separated by commas) _NUMBER_DECIMAL_COMMA: the mark '.' or ','. */
static size_t digits_at(const char* s, const size_t n, size_t* i)
{
    const size_t from = *i;
    while ((*i < n) && (s[*i] >= '0') && (s[*i] <= '9')) {
        (*i)++;
    }
    return *i - from;
}

static int is_number(const char* s, const size_t n, const int decimal_comma)
{
    size_t i = ((n > 0U) && ((s[0] == '+') || (s[0] == '-'))) ? 1U : 0U;
    size_t d = digits_at(s, n, &i);
    if ((i < n) && ((s[i] == '.') || ((decimal_comma != 0) && (s[i] == ',')))) {
        i++;
        d += digits_at(s, n, &i);
    }
    if (d == 0U) {
        return 0;
    }
    if ((i < n) && ((s[i] == 'e') || (s[i] == 'E'))) {
        i++;
        i += ((i < n) && ((s[i] == '+') || (s[i] == '-'))) ? 1U : 0U;
        if (digits_at(s, n, &i) == 0U) {
            return 0;
        }
    }
    return i == n;
}

/* A-Z lowered, every other character as it is (read_options.ascii_lower; re.IGNORECASE with
 * re.ASCII). */
static int ascii_lower(const int c) { return ((c >= 'A') && (c <= 'Z')) ? (c + ('a' - 'A')) : c; }

/* Whether the n characters at s are one of `count` words, A-Z lowered. */
static int is_one_of(const char* s, const size_t n, const char* const* words, const size_t count)
{
    int found = 0;
    for (size_t w = 0U; (w < count) && (found == 0); w++) {
        size_t i = 0U;
        while ((i < n) && (words[w][i] != '\0') && (ascii_lower(s[i]) == words[w][i])) {
            i++;
        }
        found = (i == n) && (words[w][i] == '\0');
    }
    return found;
}

/* csvio._NOT_FINITE: [+-]?(nan|inf|infinity), case aside. */
static int is_not_finite(const char* s, size_t n)
{
    static const char* const words[3] = {"nan", "inf", "infinity"};
    if ((n > 0U) && ((s[0] == '+') || (s[0] == '-'))) {
        s++;
        n--;
    }
    return is_one_of(s, n, words, 3U);
}

/* csvio.is_missing: a stripped cell of n characters is empty or one of the missing words. */
static int is_missing(const char* s, const size_t n)
{
    static const char* const words[NTE_CSV_MISSING_WORD_COUNT] = NTE_CSV_MISSING_WORDS;
    return (n == 0U) || is_one_of(s, n, words, NTE_CSV_MISSING_WORD_COUNT);
}

static int push(nte_trial_t* tr, size_t* cap, const double t, const double l, const double v,
                const double f, const size_t lineno)
{
    if (tr->n == *cap) {
        const size_t nc = (*cap == 0U) ? 1024U : (*cap * 2U);
        double** a[4] = {&tr->t_s, &tr->depth_mm, &tr->velocity_mm_s, &tr->force_n};
        for (size_t i = 0U; i < 4U; i++) {
            double* b = realloc(*a[i], nc * sizeof(double));
            if (b == NULL) {
                return -1;
            }
            *a[i] = b;
        }
        size_t* ln = realloc(tr->line, nc * sizeof(size_t));
        if (ln == NULL) {
            return -1;
        }
        tr->line = ln;
        *cap = nc;
    }
    tr->t_s[tr->n] = t;
    tr->depth_mm[tr->n] = l;
    tr->velocity_mm_s[tr->n] = v;
    tr->force_n[tr->n] = f;
    tr->line[tr->n] = lineno;
    tr->n++;
    return 0;
}

void nte_columns_standard(nte_columns_t* c)
{
    (void)snprintf(c->t, sizeof c->t, "t_s");
    (void)snprintf(c->depth, sizeof c->depth, "depth_mm");
    (void)snprintf(c->force, sizeof c->force, "force_n");
    (void)snprintf(c->velocity, sizeof c->velocity, "velocity_mm_s");
    c->velocity_required = 0;
    c->force_ignored = 0;
}

static const nte_unit_t force_units[NTE_FORCE_UNIT_COUNT] = NTE_FORCE_UNITS;
static const nte_unit_t time_units[NTE_TIME_UNIT_COUNT] = NTE_TIME_UNITS;
static const nte_unit_t depth_units[NTE_DEPTH_UNIT_COUNT] = NTE_DEPTH_UNITS;
static const char* const force_unit_words[NTE_FORCE_UNIT_NAME_WORD_COUNT] =
    NTE_FORCE_UNIT_NAME_WORDS;
static const char* const time_unit_words[NTE_TIME_UNIT_NAME_WORD_COUNT] = NTE_TIME_UNIT_NAME_WORDS;
static const char* const depth_unit_words[NTE_DEPTH_UNIT_NAME_WORD_COUNT] =
    NTE_DEPTH_UNIT_NAME_WORDS;

/* csvio._named_with_unit: the column is one of the words and the unit (or one of its
 * spellings, csvio.UNIT_NAME_SPELLINGS: the micro sign, the Greek mu) in one of the forms
 * (WORD between UNIT after), ASCII case aside. */
static int named_with_unit(const char* column, const char* const* words, const size_t n_words,
                           const char* unit)
{
    static const struct {
        const char* between;
        const char* after;
    } forms[NTE_UNIT_NAME_FORM_COUNT] = NTE_UNIT_NAME_FORMS;
    static const struct {
        const char* unit;
        const char* spelled;
    } spellings[NTE_UNIT_NAME_SPELLING_COUNT] = NTE_UNIT_NAME_SPELLINGS;
    for (size_t sp = 0U; sp <= NTE_UNIT_NAME_SPELLING_COUNT; sp++) {
        /* sp == 0: the unit as the options call it; then each other spelling of it */
        const char* spelled = (sp == 0U) ? unit : spellings[sp - 1U].spelled;
        if ((sp > 0U) && (strcmp(spellings[sp - 1U].unit, unit) != 0)) {
            continue;
        }
        for (size_t w = 0U; w < n_words; w++) {
            for (size_t f = 0U; f < NTE_UNIT_NAME_FORM_COUNT; f++) {
                char name[64];
                (void)snprintf(name, sizeof name, "%s%s%s%s", words[w], forms[f].between, spelled,
                               forms[f].after);
                if (nte_py_ascii_same(column, strlen(column), name) != 0) {
                    return 1;
                }
            }
        }
    }
    return 0;
}

/* Python's shlex.quote (read_options.unit_suffix_hint calls it): the text as it is when every
 * character is a letter, a digit or one of _@%+=:,./- ; else inside single quotes, a ' written
 * '"'"'. */
static void shell_quoted(const char* text, char* out, const size_t cap)
{
    static const char safe[] = "_@%+=:,./-";
    int plain = (text[0] != '\0');
    for (const char* c = text; *c != '\0'; c++) {
        const int alnum = ((*c >= 'a') && (*c <= 'z')) || ((*c >= 'A') && (*c <= 'Z')) ||
                          ((*c >= '0') && (*c <= '9'));
        plain &= alnum || (strchr(safe, *c) != NULL);
    }
    if (plain != 0) {
        (void)snprintf(out, cap, "%s", text);
        return;
    }
    size_t o = 0U;
    out[o++] = '\'';
    for (const char* c = text; (*c != '\0') && (o + 6U < cap); c++) {
        if (*c == '\'') {
            (void)memcpy(out + o, "'\"'\"'", 5U);
            o += 5U;
        } else {
            out[o++] = *c;
        }
    }
    out[o++] = '\'';
    out[o] = '\0';
}

/* Twin of csvio.unit_suffix_hint: "read it with --columns t=..,depth=..,force=.. [--KIND-unit
 * U]..." (the map quoted for the shell where a name needs it) when each of the time, depth and
 * force has exactly one column named by its quantity, with its unit (t_ms, depth_m, "Force
 * [mN]": csvio's UNIT_SUFFIX_QUANTITIES and UNIT_NAME_FORMS) or without ("Time": the tools'
 * own unit), "" otherwise.  The reader does not guess from a name (a column so named may hold
 * anything); the refusal says how to read the file. */
static void unit_suffix_hint(char* const* header, const size_t nc, char* out, const size_t cap)
{
    const struct {
        const char* key;  /* the --columns key */
        const char* kind; /* --KIND-unit */
        const char* const* words;
        size_t n_words;
        const nte_unit_t* units;
        size_t n_units;
    } quantities[NTE_UNIT_QUANTITY_COUNT] = NTE_UNIT_QUANTITIES;
    char mapped[512] = "";
    char options[256] = "";
    out[0] = '\0';
    for (size_t q = 0U; q < NTE_UNIT_QUANTITY_COUNT; q++) {
        size_t found = 0U;
        const char* column = NULL;
        const nte_unit_t* unit = NULL;
        size_t unit_index = 0U;
        for (size_t c = 0U; c < nc; c++) {
            /* a word alone: the tools' own unit (the first of the table) */
            for (size_t w = 0U; w < quantities[q].n_words; w++) {
                if (nte_py_ascii_same(header[c], strlen(header[c]), quantities[q].words[w]) != 0) {
                    found++;
                    column = header[c];
                    unit = &quantities[q].units[0];
                    unit_index = 0U;
                }
            }
            for (size_t u = 0U; u < quantities[q].n_units; u++) {
                if (named_with_unit(header[c], quantities[q].words, quantities[q].n_words,
                                    quantities[q].units[u].name) != 0) {
                    found++;
                    column = header[c];
                    unit = &quantities[q].units[u];
                    unit_index = u;
                }
            }
        }
        if (found != 1U) {
            return;
        }
        size_t o = strlen(mapped);
        (void)snprintf(mapped + o, sizeof mapped - o, "%s%s=%s", (q > 0U) ? "," : "",
                       quantities[q].key, column);
        if (unit_index != 0U) { /* the first unit of each table is the tools' own */
            o = strlen(options);
            (void)snprintf(options + o, sizeof options - o, " --%s-unit %s", quantities[q].kind,
                           unit->name);
        }
    }
    char quoted[1100];
    shell_quoted(mapped, quoted, sizeof quoted);
    (void)snprintf(out, cap, "; read it with --columns %s%s", quoted, options);
}

/* What the reader knows between records. */
typedef struct table_t {
    const char* path;
    const nte_columns_t* cols;
    nte_trial_t* tr;
    char* names;   /* the header's record, each name stripped in place */
    char** header; /* the names */
    size_t ncols;  /* 0: no header yet */
    size_t header_line;
    int idx[4]; /* t, depth, force, velocity: the column, or -1 */
    int truth;  /* the NTE_CSV_TRUTH_COLUMN column, or -1 */
    double* row;
    double prev_t;
    int time_form; /* the time column's: -1 numbers, 0 times of day, 1 dates and times, 2 not
                    * yet known (csvio._TimeColumn) */
    nte_clock_column_t clock;
    int first_record; /* 1: no record read after the header yet (a units row may come) */
    char* preamble;   /* the refusal of a line before the header (a logger's preamble) as one,
                       * to give if no header comes: the first that advises, else the first */
    int preamble_advised;
    size_t preamble_last_width; /* the cells of the last line refused as the header */
    size_t cap;
    char* err;
    size_t es;
} table_t;

/* Whether position c + 1 is one of the n positions `at` (from 1). */
static int among(const unsigned long* at, const size_t n, const size_t c)
{
    int found = 0;
    for (size_t k = 0U; k < n; k++) {
        found |= (at[k] == c + 1U);
    }
    return found;
}

/* Whether a record is a sample's, not a preamble's or a header's (csvio._is_data): two cells
 * at least, each a number or missing, a number among them.  at: NULL, every cell is judged;
 * else only the cells at these n_at positions (from 1): a file read by positions, whose other
 * columns are not read (a logger's state word beside its numbers). */
static int is_data(const record_t* r, const unsigned long* at, const size_t n_at)
{
    const int decimal_comma = (r->delimiter != ',');
    int numbers = 0;
    for (size_t c = 0U; c < r->n; c++) {
        if ((at != NULL) && !among(at, n_at, c)) {
            continue;
        }
        const char* cell = r->text + r->start[c];
        const size_t full = ((c + 1U < r->n) ? r->start[c + 1U] : r->len) - r->start[c] - 1U;
        const size_t n = nte_py_strip(&cell, full);
        if (is_number(cell, n, decimal_comma)) {
            numbers++;
        } else if (!is_missing(cell, n)) {
            return 0;
        }
    }
    return (r->n >= 2U) && (numbers > 0);
}

/* A record refused as the header, its refusal in tb->err (csvio.read_table's preamble): a
 * sample's (`sample`: is_data) ends the search (-1, the preamble's refusal if one was kept,
 * with the advice for a file without a header where the sample's refusal gives it
 * (`no_header`), the preamble's gives none and the line just before the sample has another
 * number of cells: one with as many is the samples' header under other names); any other is a
 * line of a logger's preamble, skipped (0), its refusal kept if it is the first, or the first
 * that advises. */
static int preamble_line(table_t* tb, const record_t* r, const int sample, const int advised,
                         const int no_header, const size_t lineno)
{
    if (sample != 0) {
        if (tb->preamble != NULL) {
            const int add = (no_header != 0) && (tb->preamble_advised == 0) &&
                            (tb->preamble_last_width != r->n);
            (void)snprintf(tb->err, tb->es, "%s%s%s", tb->preamble, add ? "; " : "",
                           add ? NTE_CSV_NO_HEADER_ADVICE : "");
        }
        return -1;
    }
    if ((tb->preamble == NULL) || ((advised != 0) && (tb->preamble_advised == 0))) {
        const size_t n = strlen(tb->err) + 1U;
        char* kept = malloc(n);
        if (kept == NULL) {
            fail(tb->err, tb->es, "%s:%zu: out of memory", tb->path, lineno);
            return -1;
        }
        (void)memcpy(kept, tb->err, n);
        free(tb->preamble);
        tb->preamble = kept;
        tb->preamble_advised = advised;
    }
    tb->preamble_last_width = r->n;
    tb->err[0] = '\0';
    tb->ncols = 0U;
    free(tb->names);
    free(tb->header);
    free(tb->row);
    tb->names = NULL;
    tb->header = NULL;
    tb->row = NULL;
    for (size_t k = 0U; k < 4U; k++) {
        tb->idx[k] = -1;
    }
    tb->truth = -1;
    return 0;
}

/* csvio._positions: a name that is a column's position, from 1, in at most 9 ASCII digits. */
static int is_position(const char* name)
{
    const size_t n = strlen(name);
    int digits = (n > 0U) && (n <= 9U) && (name[0] != '0');
    for (size_t i = 0U; (i < n) && (digits != 0); i++) {
        digits = (name[i] >= '0') && (name[i] <= '9');
    }
    return digits;
}

/* Whether column k (0 time, 1 depth, 2 force, 3 velocity) must be in the header
 * (csvio.read_trial's `named`): the force unless ignored, the velocity where the map names
 * it. */
static int is_required(const nte_columns_t* cols, const size_t k)
{
    return (k < 2U) || ((k == 2U) && (cols->force_ignored == 0)) ||
           ((k == 3U) && (cols->velocity_required != 0));
}

/* A file without a header, its columns given by their positions (csvio.read_table's
 * by_position): the names "1".."N" for the first sample's N cells.  1: the record is that
 * sample, to be taken as a row; -1: a position beyond its cells, or out of memory. */
static int numbered_header(table_t* tb, const record_t* r, const size_t lineno,
                           const char* const* want, const size_t n_req)
{
    for (size_t k = 0U; k < n_req; k++) {
        if (is_required(tb->cols, k) && (strtoul(want[k], NULL, 10) > r->n)) {
            fail(tb->err, tb->es,
                 "%s:%zu: column '%s': no such position: the first sample has %zu cells", tb->path,
                 lineno, want[k], r->n);
            return -1;
        }
    }
    enum { width = 24 }; /* a size_t in decimal, and its '\0' */
    free(tb->names);
    tb->names = malloc(r->n * width);
    if (tb->names == NULL) {
        fail(tb->err, tb->es, "%s:%zu: out of memory", tb->path, lineno);
        return -1;
    }
    for (size_t k = 0U; k < 4U; k++) {
        tb->idx[k] = -1;
    }
    tb->truth = -1;
    for (size_t c = 0U; c < r->n; c++) {
        tb->header[c] = tb->names + (c * width);
        (void)snprintf(tb->header[c], width, "%zu", c + 1U);
        for (size_t k = 0U; k < 4U; k++) {
            if ((tb->idx[k] < 0) && (strcmp(tb->header[c], want[k]) == 0)) {
                tb->idx[k] = (int)c;
            }
        }
    }
    tb->header_line = 0U;
    return 1;
}

/* The header: names stripped, the required columns there (else the file's names and, for the
 * standard names, how to read a unit in a name), no name twice.  A sample where the names
 * read are positions: numbered_header. */
static int take_header(table_t* tb, const record_t* r, const size_t lineno)
{
    const nte_columns_t* cols = tb->cols;
    tb->names = malloc(r->len);
    tb->header = malloc(r->n * sizeof *tb->header);
    tb->row = malloc(r->n * sizeof *tb->row);
    if ((tb->names == NULL) || (tb->header == NULL) || (tb->row == NULL)) {
        fail(tb->err, tb->es, "%s:%zu: out of memory", tb->path, lineno);
        return -1;
    }
    (void)memcpy(tb->names, r->text, r->len);
    const char* want[4] = {cols->t, cols->depth, cols->force, cols->velocity};
    for (size_t c = 0U; c < r->n; c++) {
        const char* name = tb->names + r->start[c];
        const size_t n = nte_py_strip(&name, strlen(name));
        tb->header[c] = (char*)name;
        tb->header[c][n] = '\0';
        for (size_t k = 0U; k < 4U; k++) {
            if ((tb->idx[k] < 0) && (want[k][0] != '\0') && (strcmp(name, want[k]) == 0)) {
                tb->idx[k] = (int)c;
            }
        }
        if ((tb->truth < 0) && (strcmp(name, NTE_CSV_TRUTH_COLUMN) == 0)) {
            tb->truth = (int)c;
        }
    }
    tb->ncols = r->n;
    tb->header_line = lineno;
    tb->first_record = 1;
    const size_t n_req = (cols->velocity_required != 0) ? 4U : 3U;
    int absent = 0;
    int positional = 1;
    unsigned long at[4] = {0U, 0U, 0U, 0U}; /* the positions read, where they are positions */
    for (size_t k = 0U; k < n_req; k++) {
        if (is_required(cols, k)) {
            absent |= (tb->idx[k] < 0);
            positional &= is_position(want[k]);
            at[k] = is_position(want[k]) ? strtoul(want[k], NULL, 10) : 0U;
        }
    }
    /* where every name read is a position, the cells at them decide whether this is a sample */
    const int sample = is_data(r, (positional != 0) ? at : NULL, n_req);
    const int by_position = sample && positional;
    if ((absent != 0) && (by_position != 0)) {
        return numbered_header(tb, r, lineno, want, n_req);
    }
    for (size_t k = 0U; k < n_req; k++) {
        if ((tb->idx[k] < 0) && is_required(cols, k)) {
            int o = snprintf(tb->err, tb->es,
                             "%s:%zu: column '%s': missing from the header (have: ", tb->path,
                             lineno, want[k]);
            for (size_t c = 0U; (c < r->n) && (o >= 0) && ((size_t)o < tb->es); c++) {
                o += snprintf(tb->err + o, tb->es - (size_t)o, "%s%s", (c > 0U) ? ", " : "",
                              tb->header[c]);
            }
            char advice[1024] = "";
            if (cols->mapped == 0) {
                unit_suffix_hint(tb->header, r->n, advice, sizeof advice);
            }
            const int no_header = (cols->mapped == 0) && (advice[0] == '\0') && (sample != 0);
            if (no_header != 0) {
                (void)snprintf(advice, sizeof advice, "; %s", NTE_CSV_NO_HEADER_ADVICE);
            }
            if ((o >= 0) && ((size_t)o < tb->es)) {
                (void)snprintf(tb->err + o, tb->es - (size_t)o, ")%s", advice);
            }
            return preamble_line(tb, r, sample, advice[0] != '\0', no_header, lineno);
        }
    }
    for (size_t a = 0U; a < r->n; a++) {
        for (size_t b = a + 1U; b < r->n; b++) {
            if (strcmp(tb->header[a], tb->header[b]) == 0) {
                fail(tb->err, tb->es, "%s:%zu: column '%s': duplicate column name in the header",
                     tb->path, lineno, tb->header[a]);
                return -1;
            }
        }
    }
    return 0;
}

/* Cell c of a record, stripped as csvio strips every cell (str.strip): where it begins in the
 * record's text (an offset: the caller may write there) and its length in *n. */
static size_t stripped_cell(const record_t* r, const size_t c, size_t* n)
{
    const char* cell = r->text + r->start[c];
    const size_t full = ((c + 1U < r->n) ? r->start[c + 1U] : r->len) - r->start[c] - 1U;
    *n = nte_py_strip(&cell, full);
    return (size_t)(cell - r->text);
}

/* Whether key k (1 depth, 2 force, 3 velocity) is read from a column whose missing value
 * leaves its row out (csvio.read_trial's skip_missing): in the file, and not an ignored force
 * (a missing one keeps its row, as NaN). */
static int is_skip_key(const table_t* tb, const size_t k)
{
    return (tb->idx[k] >= 0) && !((k == 2U) && (tb->cols->force_ignored != 0));
}

static int is_skip_column(const table_t* tb, const size_t c)
{
    int found = 0;
    for (size_t k = 1U; k < 4U; k++) {
        found = found || (is_skip_key(tb, k) && ((int)c == tb->idx[k]));
    }
    return found;
}

/* A row left out: counted, its line kept among the first NTE_CSV_LEFT_OUT_LISTED. */
static void count_left_out(size_t* count, size_t* lines, const size_t lineno)
{
    if (*count < NTE_CSV_LEFT_OUT_LISTED) {
        lines[*count] = lineno;
    }
    (*count)++;
}

/* The first record after the header as a units row (csvio._units_row): no cell a number, one
 * of the time's, depth's and force's cells at least read as a unit (nte_unit_like).  1: it is
 * one, those three cells kept in the trial where not empty; 0: it is not; -1: out of memory. */
static int take_units_row(table_t* tb, const record_t* r, const size_t lineno)
{
    const int decimal_comma = (r->delimiter != ',');
    for (size_t c = 0U; c < r->n; c++) {
        size_t n = 0U;
        const size_t at = stripped_cell(r, c, &n);
        if (is_number(r->text + at, n, decimal_comma)) {
            return 0;
        }
    }
    int units = 0;
    for (size_t k = 0U; (k < 3U) && (units == 0); k++) {
        size_t n = 0U;
        if (tb->idx[k] >= 0) {
            const char* cell = r->text + stripped_cell(r, (size_t)tb->idx[k], &n);
            units = nte_unit_like(cell, n);
        }
    }
    if (units == 0) {
        return 0;
    }
    for (size_t k = 0U; k < 3U; k++) {
        size_t n = 0U;
        if (tb->idx[k] < 0) {
            continue;
        }
        const char* cell = r->text + stripped_cell(r, (size_t)tb->idx[k], &n);
        if (n > 0U) {
            tb->tr->units_row[k] = malloc(n + 1U);
            if (tb->tr->units_row[k] == NULL) {
                fail(tb->err, tb->es, "%s:%zu: out of memory", tb->path, lineno);
                return -1;
            }
            (void)memcpy(tb->tr->units_row[k], cell, n);
            tb->tr->units_row[k][n] = '\0';
        }
    }
    tb->tr->units_row_line = lineno;
    return 1;
}

/* The time column's cell (csvio._TimeColumn.read): a clock time while the column is one and in
 * the first row's form; otherwise a number.  1: *t is the time; 0: a number to read; -1:
 * refused. */
static int time_cell(table_t* tb, const char* cell, const size_t n, const int decimal_comma,
                     const size_t lineno, double* t)
{
    static const char* const forms[2] = {"a time of day", "a date and time"};
    nte_stamp_t stamp;
    if ((tb->time_form >= 0) && (nte_clock_read_stamp(cell, n, decimal_comma, &stamp) != 0) &&
        ((tb->time_form == 2) || (tb->time_form == stamp.dated))) {
        tb->time_form = stamp.dated;
        *t = nte_clock_seconds(&tb->clock, &stamp);
        return 1;
    }
    if (tb->time_form >= 0 && tb->time_form < 2) {
        char shown[512];
        nte_py_repr_bytes(cell, n, shown, sizeof shown);
        fail(tb->err, tb->es, "%s:%zu: column '%s': not %s as in the first row: %s", tb->path,
             lineno, tb->header[tb->idx[0]], forms[tb->time_form], shown);
        return -1;
    }
    tb->time_form = -1;
    return 0;
}

/* Whether column c is one the reader reads (csvio.read_table's `read`): the time, depth,
 * force, velocity and truth (NTE_CSV_TRUTH_COLUMN) columns.  The others' cells are not looked
 * at: a logger's state word or a note does not make a sample refused. */
static int is_read(const table_t* tb, const size_t c)
{
    int found = ((int)c == tb->truth);
    for (size_t k = 0U; k < 4U; k++) {
        found = found || ((int)c == tb->idx[k]);
    }
    return found;
}

/* A sample: as many cells as the header, each a finite decimal number, the time increasing;
 * or a dropout: a depth, force or velocity missing, the row left out (its line counted), its
 * other cells numbers or missing, its time not compared; or a repeat: the time equal to the
 * previous sample's, the row left out (its line counted).  A decimal comma is made a point in
 * place (the cell is read once). */
static int take_row(table_t* tb, record_t* r, const size_t lineno)
{
    if (r->n != tb->ncols) {
        fail(tb->err, tb->es, "%s:%zu: expected %zu cells, found %zu", tb->path, lineno, tb->ncols,
             r->n);
        return -1;
    }
    if (tb->first_record != 0) {
        tb->first_record = 0;
        const int units = take_units_row(tb, r, lineno);
        if (units != 0) {
            return (units > 0) ? 0 : -1;
        }
    }
    int nothing_read = 1;
    for (size_t c = 0U; (c < r->n) && (nothing_read != 0); c++) {
        size_t n = 0U;
        (void)stripped_cell(r, c, &n);
        nothing_read = !is_read(tb, c) || (n == 0U);
    }
    if (nothing_read != 0) {
        return 0; /* nothing in the columns read: another sensor's line, not a sample */
    }
    int skip = 0;
    for (size_t c = 0U; (c < r->n) && (skip == 0); c++) {
        size_t n = 0U;
        const size_t at = stripped_cell(r, c, &n);
        skip = is_skip_column(tb, c) && is_missing(r->text + at, n);
    }
    for (size_t c = 0U; c < r->n; c++) {
        if (!is_read(tb, c)) {
            tb->row[c] = (double)NAN;
            continue;
        }
        size_t n = 0U;
        char* cell = r->text + stripped_cell(r, c, &n);
        if (((skip != 0) || (((int)c == tb->idx[2]) && (tb->cols->force_ignored != 0))) &&
            is_missing(cell, n)) {
            tb->row[c] = (double)NAN;
            continue;
        }
        const int decimal_comma = (r->delimiter != ',');
        if ((int)c == tb->idx[0]) {
            const int clock = time_cell(tb, cell, n, decimal_comma, lineno, &tb->row[c]);
            if (clock < 0) {
                return -1;
            }
            if (clock > 0) {
                continue;
            }
        }
        const int number = is_number(cell, n, decimal_comma);
        if (number && decimal_comma) {
            char* mark = memchr(cell, ',', n);
            if (mark != NULL) {
                *mark = '.';
            }
        }
        tb->row[c] = number ? strtod(cell, NULL) : 0.0;
        if (!number || !isfinite(tb->row[c])) {
            char shown[512];
            nte_py_repr_bytes(cell, n, shown, sizeof shown);
            fail(tb->err, tb->es, "%s:%zu: column '%s': %s: %s", tb->path, lineno, tb->header[c],
                 (number || is_not_finite(cell, n)) ? "not finite" : "not a number", shown);
            return -1;
        }
    }
    if (skip != 0) {
        count_left_out(&tb->tr->left_out, tb->tr->left_out_line, lineno);
        return 0;
    }
    const double t = tb->row[tb->idx[0]];
    if ((t >= tb->prev_t) && (t <= tb->prev_t)) {
        /* a repeat (the same time, exactly): the library would reject it (not later than the
         * last sample) */
        count_left_out(&tb->tr->repeated, tb->tr->repeated_line, lineno);
        return 0;
    }
    if (!(t > tb->prev_t)) {
        char a[40];
        char b[40];
        nte_py_repr(t, a, sizeof a);
        nte_py_repr(tb->prev_t, b, sizeof b);
        fail(tb->err, tb->es, "%s:%zu: column '%s': time %s does not increase (previous %s)",
             tb->path, lineno, tb->cols->t, a, b);
        return -1;
    }
    tb->prev_t = t;
    const int vi = tb->idx[3];
    const int fi = tb->idx[2];
    if (push(tb->tr, &tb->cap, t, tb->row[tb->idx[1]], (vi >= 0) ? tb->row[vi] : 0.0,
             (fi >= 0) ? tb->row[fi] : (double)NAN, lineno) != 0) {
        fail(tb->err, tb->es, "%s:%zu: out of memory", tb->path, lineno);
        return -1;
    }
    return 0;
}

/* One record: a blank line (no cell, or only blank cells, a spreadsheet's ",,": skipped), the
 * header, or a sample. */
static int take(table_t* tb, record_t* r, const size_t lineno)
{
    int blank = 1;
    for (size_t c = 0U; (c < r->n) && (blank != 0); c++) {
        size_t n = 0U;
        (void)stripped_cell(r, c, &n);
        blank = (n == 0U);
    }
    if (blank != 0) {
        return 0;
    }
    if (tb->ncols == 0U) {
        const int header = take_header(tb, r, lineno);
        return (header == 1) ? take_row(tb, r, lineno) : header;
    }
    return take_row(tb, r, lineno);
}

/* csvio.read_table's records: where the first line that is not blank does not hold the names
 * read (a logger's preamble), the separator of the first later line that does (holding), if one
 * does, into *delimiter: 1, else 0.  The lines from text[pos] on (line numbers after `lineno`)
 * are read as the reader reads them: one that is not UTF-8 is refused here (-1, as csvio's
 * look-ahead decodes it), a comment skipped. */
static int preamble_separator(const char* text, const size_t len, size_t pos, size_t lineno,
                              const char* path, const char* const* want, const size_t n_want,
                              char* delimiter, char* err, const size_t es)
{
    while (pos < len) {
        const char* line = text + pos;
        const char* nl = memchr(line, '\n', len - pos);
        const size_t n = (nl != NULL) ? ((size_t)(nl - line) + 1U) : (len - pos);
        pos += n;
        lineno++;
        if (!nte_py_utf8(line, n)) {
            fail(err, es, "%s:%zu: not UTF-8 text", path, lineno);
            return -1;
        }
        if ((n > 0U) && (line[0] == NTE_CSV_COMMENT)) {
            continue;
        }
        const char d = holding(line, n, want, n_want);
        if (d != 0) {
            *delimiter = d;
            return 1;
        }
    }
    return 0;
}

/* A line of the file (a BOM on the first dropped): the bytes from text[*pos] to the next '\n'
 * included; *pos moves past it. */
static const char* next_line(const char* text, const size_t len, size_t* pos, const size_t lineno,
                             size_t* n)
{
    const char* line = text + *pos;
    const char* nl = memchr(line, '\n', len - *pos);
    *n = (nl != NULL) ? ((size_t)(nl - line) + 1U) : (len - *pos);
    *pos += *n;
    if ((lineno == 1U) && (*n >= 3U) && (memcmp(line, "\xef\xbb\xbf", 3U) == 0)) {
        line += 3;
        *n -= 3U;
    }
    return line;
}

/* csvio._advising: the separator a leading comment's names are cut at (its first of ',', ';',
 * '\t', else BLANKS) when unit_suffix_hint advises on those names (cut_names); 0 when it does
 * not, or out of memory. */
static char advising(const char* line, const size_t n)
{
    int seen[3];
    separators_seen(line, n, seen);
    char d = BLANKS;
    for (size_t k = 3U; k > 0U; k--) {
        if (seen[k - 1U] != 0) {
            d = separators[k - 1U];
        }
    }
    char* text = malloc(n + 1U);
    char** names = malloc((n + 1U) * sizeof *names);
    char advice[1024] = "";
    size_t* lengths = malloc((n + 1U) * sizeof *lengths);
    if ((text != NULL) && (names != NULL) && (lengths != NULL)) {
        unit_suffix_hint(names, cut_names(line, n, d, text, names, lengths), advice, sizeof advice);
    }
    free(text);
    free(names);
    free(lengths);
    if (advice[0] == '\0') {
        d = 0;
    }
    return d;
}

/* csvio.read_table's leading comments: the last comment line before text[upto] (the first line
 * that is neither blank nor a comment) that, without its mark, holds the names read -- else,
 * with `advise`, the last whose names unit_suffix_hint advises on (advising) -- 1, its text
 * after the mark in *at, *n, its number in *number and its separator in *delimiter (a header
 * as numpy.savetxt writes it, "# t_s depth_mm force_n"); 0 when none does. */
static int header_comment(const char* text, const size_t upto, const char* const* want,
                          const size_t n_want, const int advise, const char** at, size_t* n,
                          size_t* number, char* delimiter)
{
    for (int pass = 0; pass < (advise ? 2 : 1); pass++) {
        int found = 0;
        size_t lineno = 0U;
        for (size_t pos = 0U; pos < upto;) {
            size_t m = 0U;
            lineno++;
            const char* line = next_line(text, upto, &pos, lineno, &m);
            char d = 0;
            if ((m > 0U) && (line[0] == NTE_CSV_COMMENT)) {
                if (pass == 0) {
                    d = holding(line + 1, m - 1U, want, n_want);
                } else {
                    d = advising(line + 1, m - 1U);
                }
            }
            if (d != 0) {
                *at = line + 1;
                *n = m - 1U;
                *number = lineno;
                *delimiter = d;
                found = 1;
            }
        }
        if (found != 0) {
            return 1;
        }
    }
    return 0;
}

/* One line into the csv state machine (as the csv module is fed a line, then its end), the
 * spaces and tabs before its break dropped where cells are cut at BLANKS; the record is taken
 * when the line completes it.  0, or -1 with the reason in the table's err. */
static int feed_line(table_t* tb, record_t* r, const char* line, const size_t n,
                     const size_t lineno)
{
    int e = 0;
    size_t brk = 0U;
    const size_t body = (r->delimiter == BLANKS) ? trailing_blanks(line, n, &brk) : n;
    for (size_t i = 0U; (i < body) && (e == 0); i++) {
        e = feed(r, (unsigned char)line[i]);
    }
    for (size_t i = n - brk; (i < n) && (e == 0); i++) {
        e = feed(r, (unsigned char)line[i]);
    }
    e = (e == 0) ? feed(r, EOL) : e;
    if (e == CSV_FIELD_LIMIT) {
        fail(tb->err, tb->es, "%s:%zu: field larger than field limit (%u)", tb->path, lineno,
             (unsigned)NTE_CSV_FIELD_LIMIT);
        return -1;
    }
    if (e != 0) {
        fail(tb->err, tb->es, "%s:%zu: %s", tb->path, lineno,
             (e == CSV_NEWLINE) ? "new-line character seen in unquoted field - do you need "
                                  "to open the file in universal-newline mode?"
                                : "out of memory");
        return -1;
    }
    if (r->state != start_record) {
        return 0;
    }
    const int rc = take(tb, r, lineno);
    record_reset(r);
    return rc;
}

/* csvio.read_table's read-ahead replayed: the lines before text[upto] -- blank lines and
 * comments only, as the first other line is there -- fed in order once the separator is known:
 * the blank ones, and the comment on line `cline` (0: none) as the header, its text after the
 * mark comment[0..cn). */
static int feed_leading(table_t* tb, record_t* r, const char* text, const size_t upto,
                        const size_t cline, const char* comment, const size_t cn)
{
    int rc = 0;
    size_t lineno = 0U;
    for (size_t pos = 0U; (pos < upto) && (rc == 0);) {
        size_t n = 0U;
        lineno++;
        const char* line = next_line(text, upto, &pos, lineno, &n);
        if (lineno == cline) {
            rc = feed_line(tb, r, comment, cn, lineno);
        } else if ((n == 0U) || (line[0] != NTE_CSV_COMMENT)) {
            rc = feed_line(tb, r, line, n, lineno);
        } else {
            /* a comment */
        }
    }
    return rc;
}

int nte_trial_read(const char* path, nte_trial_t* tr, char* err, const size_t es)
{
    nte_columns_t c;
    (void)memset(&c, 0, sizeof c);
    nte_columns_standard(&c);
    return nte_trial_read_columns(path, &c, tr, err, es);
}

int nte_trial_read_columns(const char* path, const nte_columns_t* cols, nte_trial_t* tr, char* err,
                           const size_t es)
{
    memset(tr, 0, sizeof *tr);
    size_t len = 0U;
    errno = 0;
    char* text = nte_file_read_all(path, &len);
    if (text == NULL) {
        fail(err, es, "%s: cannot read: %s", path, strerror((errno != 0) ? errno : EIO));
        return -1;
    }
    table_t tb;
    (void)memset(&tb, 0, sizeof tb);
    tb.path = path;
    tb.cols = cols;
    tb.tr = tr;
    tb.prev_t = -HUGE_VAL;
    tb.time_form = 2;
    tb.err = err;
    tb.es = es;
    for (size_t k = 0U; k < 4U; k++) {
        tb.idx[k] = -1;
    }
    tb.truth = -1;
    record_t r;
    (void)memset(&r, 0, sizeof r);
    record_reset(&r);
    r.delimiter = ',';
    /* the columns read (as csvio.read_trial requires them), which the separator must keep */
    const char* want[4] = {cols->t, cols->depth, NULL, NULL};
    size_t n_want = 2U;
    if (cols->force_ignored == 0) {
        want[n_want++] = cols->force;
    }
    if (cols->velocity_required != 0) {
        want[n_want++] = cols->velocity;
    }
    int decided = 0; /* the delimiter, from the first line that is not blank */
    int rc = 0;
    size_t lineno = 0U;
    /* csvio's lines: split after every '\n', decoded (the first without its BOM), a comment
     * skipped wherever it stands; each fed to the csv reader, character by character */
    for (size_t pos = 0U; (pos < len) && (rc == 0);) {
        const size_t start = pos;
        size_t n = 0U;
        lineno++;
        const char* line = next_line(text, len, &pos, lineno, &n);
        if (!nte_py_utf8(line, n)) {
            fail(err, es, "%s:%zu: not UTF-8 text", path, lineno);
            rc = -1;
            break;
        }
        if ((n > 0U) && (line[0] == NTE_CSV_COMMENT)) {
            continue;
        }
        const char* visible = line;
        if ((decided == 0) && (nte_py_strip(&visible, n) == 0U)) {
            continue; /* a blank line before the first other: read once the separator is known */
        }
        if (decided == 0) {
            r.delimiter = delimiter_of(line, n, want, n_want);
            decided = 1;
            int held = names_hold(line, n, r.delimiter, want, n_want);
            if (held == 0) {
                held = preamble_separator(text, len, pos, lineno, path, want, n_want, &r.delimiter,
                                          err, es);
                rc = (held < 0) ? -1 : 0;
            }
            size_t cline = 0U;
            const char* comment = NULL;
            size_t cn = 0U;
            if ((held == 0) && !header_comment(text, start, want, n_want, cols->mapped == 0,
                                               &comment, &cn, &cline, &r.delimiter)) {
                cline = 0U;
            }
            rc = (rc == 0) ? feed_leading(&tb, &r, text, start, cline, comment, cn) : rc;
            if (rc != 0) {
                break;
            }
        }
        rc = feed_line(&tb, &r, line, n, lineno);
    }
    if ((rc == 0) && (decided == 0)) {
        rc = feed_leading(&tb, &r, text, len, 0U, NULL, 0U); /* a file of blank lines */
    }
    /* the end of the file inside quotes (or a cell): that record is the last */
    if ((rc == 0) && ((r.chars != 0U) || (r.state == in_quoted))) {
        rc = save_field(&r);
        if (rc != 0) {
            fail(err, es, "%s:%zu: out of memory", path, lineno);
        } else {
            rc = take(&tb, &r, lineno);
        }
    }
    if ((rc == 0) && (tr->n == 0U) && (tr->left_out > 0U)) {
        /* the columns that leave a row out, in the map's order (depth, force, velocity), as
         * csvio names them (before the header is freed) */
        int o = snprintf(err, es,
                         "%s:%zu: no sample: every row after the header has a value "
                         "missing in column '",
                         path, tr->left_out_line[0]);
        size_t named = 0U;
        for (size_t k = 1U; (k < 4U) && (o >= 0) && ((size_t)o < es); k++) {
            if (is_skip_key(&tb, k)) {
                o += snprintf(err + o, es - (size_t)o, "%s%s", (named > 0U) ? "' or '" : "",
                              tb.header[tb.idx[k]]);
                named++;
            }
        }
        if ((o >= 0) && ((size_t)o < es)) {
            (void)snprintf(err + o, es - (size_t)o, "' (%zu rows)", tr->left_out);
        }
        rc = -1;
    }
    tr->clock = (tb.time_form == 0) || (tb.time_form == 1);
    free(text);
    free(r.text);
    free(r.start);
    free(tb.names);
    free(tb.header);
    free(tb.row);
    if ((rc == 0) && (tb.ncols == 0U)) {
        if (tb.preamble != NULL) {
            (void)snprintf(err, es, "%s", tb.preamble);
        } else {
            fail(err, es, "%s:1: no header line", path);
        }
        rc = -1;
    }
    free(tb.preamble);
    if ((rc == 0) && (tr->n == 0U)) {
        fail(err, es, "%s:%zu: no samples after the header", path, tb.header_line + 1U);
        rc = -1;
    }
    if (rc != 0) {
        nte_trial_free(tr);
        return -1;
    }
    tr->velocity_given = (tb.idx[3] >= 0);
    if (tb.idx[3] < 0) {
        nte_central_difference(tr->t_s, tr->depth_mm, tr->n, tr->velocity_mm_s);
    }
    return 0;
}

/* One line of the note: "PATH: K of TOTAL rows left out, WHY: lines A, B and N more)" at
 * out + o; returns the new end (cap when the note is cut). */
static size_t left_out_line(char* out, const size_t cap, size_t o, const char* path,
                            const size_t* lines, const size_t k, const size_t total,
                            const char* why)
{
    int w = snprintf(out + o, cap - o, "%s: %zu of %zu rows left out, %s: line%s", path, k, total,
                     why, (k > 1U) ? "s" : "");
    for (size_t i = 0U;
         (i < k) && (i < NTE_CSV_LEFT_OUT_LISTED) && (w >= 0) && ((size_t)w < cap - o); i++) {
        o += (size_t)w;
        w = snprintf(out + o, cap - o, "%s%zu", (i > 0U) ? ", " : " ", lines[i]);
    }
    if ((w >= 0) && ((size_t)w < cap - o)) {
        o += (size_t)w;
        w = (k > NTE_CSV_LEFT_OUT_LISTED)
                ? snprintf(out + o, cap - o, " and %zu more)", k - NTE_CSV_LEFT_OUT_LISTED)
                : snprintf(out + o, cap - o, ")");
    }
    return ((w >= 0) && ((size_t)w < cap - o)) ? o + (size_t)w : cap;
}

void nte_trial_left_out_note(const char* path, const nte_trial_t* tr, const nte_columns_t* cols,
                             char* out, const size_t cap)
{
    out[0] = '\0';
    const size_t total = tr->n + tr->left_out + tr->repeated;
    size_t o = 0U;
    if (tr->left_out > 0U) {
        /* the columns that leave a row out (csvio.Trial.left_out_columns) */
        const int force = (cols->force_ignored == 0);
        const int velocity = (tr->velocity_given != 0);
        char why[4U * NTE_COLUMN_NAME_MAX + 64U];
        (void)snprintf(why, sizeof why, "a value missing in column '%s%s%s%s%s' (a dropout",
                       cols->depth, force ? "' or '" : "", force ? cols->force : "",
                       velocity ? "' or '" : "", velocity ? cols->velocity : "");
        o = left_out_line(out, cap, o, path, tr->left_out_line, tr->left_out, total, why);
    }
    if ((tr->repeated > 0U) && (o + 1U < cap)) {
        if (o > 0U) {
            out[o++] = '\n';
            out[o] = '\0';
        }
        (void)left_out_line(out, cap, o, path, tr->repeated_line, tr->repeated, total,
                            "the time equal to the previous sample's (a repeat");
    }
}

void nte_trial_free(nte_trial_t* tr)
{
    free(tr->t_s);
    free(tr->depth_mm);
    free(tr->velocity_mm_s);
    free(tr->force_n);
    free(tr->line);
    for (size_t k = 0U; k < 3U; k++) {
        free(tr->units_row[k]);
    }
    memset(tr, 0, sizeof *tr);
}

void nte_trial_convert(nte_trial_t* tr, const nte_units_t* u)
{
    const double kt = u->time_factor;
    const double kd = u->depth_factor * (double)u->depth_sign;
    const double kf = u->force_factor * (double)u->force_sign;
    const double kv = kd / kt;
    /* the reference adds no offset of 0 (a depth of -0.0 stays -0.0) */
    const int offset = (u->depth_offset_mm < 0.0) || (u->depth_offset_mm > 0.0);
    for (size_t k = 0U; k < tr->n; k++) {
        tr->t_s[k] *= kt;
        tr->depth_mm[k] *= kd;
        if (offset) {
            tr->depth_mm[k] += u->depth_offset_mm;
        }
        tr->force_n[k] *= kf;
        if (tr->velocity_given != 0) {
            tr->velocity_mm_s[k] *= kv;
        }
    }
    if (tr->velocity_given == 0) {
        nte_central_difference(tr->t_s, tr->depth_mm, tr->n, tr->velocity_mm_s);
    }
}

void nte_central_difference(const double* t, const double* x, const size_t n, double* v)
{
    if (n < 2U) {
        for (size_t k = 0U; k < n; k++) {
            v[k] = 0.0;
        }
        return;
    }
    v[0] = (x[1] - x[0]) / (t[1] - t[0]);
    for (size_t k = 1U; k < (n - 1U); k++) {
        v[k] = (x[k + 1U] - x[k - 1U]) / (t[k + 1U] - t[k - 1U]);
    }
    v[n - 1U] = (x[n - 1U] - x[n - 2U]) / (t[n - 1U] - t[n - 2U]);
}

void nte_trial_sample(const nte_trial_t* tr, size_t k, int force_ignored, nte_sample_t* s)
{
    s->t_us = (int64_t)floor((tr->t_s[k] * 1e6) + 0.5);
    s->depth_mm = (nte_real_t)tr->depth_mm[k];
    s->velocity_mm_s = (nte_real_t)tr->velocity_mm_s[k];
    s->force_n = (force_ignored != 0) ? (nte_real_t)0 : (nte_real_t)tr->force_n[k];
}
