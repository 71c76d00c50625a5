/*
 * Python's text rules, for the host programs' messages: repr() of a float and of a text,
 * str.strip(), UTF-8 as Python decodes it (the tables they need are generated from Python into
 * nte_units.h; tests/python/test_py_text.py holds them to Python's).  And a comma-separated
 * NAME=VALUE list as the Python tools split one (--start, --columns): the items at every ',',
 * each partitioned at its first '=', every part stripped (str.split, str.partition,
 * str.strip).  Host only.
 */
#ifndef NTE_NAME_VALUE_H
#define NTE_NAME_VALUE_H

#include <stddef.h>

#define NTE_NV_TEXT 1024U /**< each part is cut to this many bytes (with its terminator) */
#define NTE_NV_MAX 16U    /**< at most this many items are split (see nte_nv_split) */

typedef struct nte_nv_t {
    char item[NTE_NV_TEXT];  /**< the whole item, stripped */
    char name[NTE_NV_TEXT];  /**< before the first '=', stripped */
    char value[NTE_NV_TEXT]; /**< after it, stripped */
    int has_eq;              /**< 0: the item holds no '=' */
} nte_nv_t;

/** Split `text` into its first NTE_NV_MAX items (a list has at least one: "" is one empty
 *  item).  Returns how many were split.  The callers refuse a list at its first bad item,
 *  and every list they accept has fewer items than NTE_NV_MAX (names appear once), so a
 *  longer list is refused within the items split. */
size_t nte_nv_split(const char* text, nte_nv_t* items, size_t max);

/** Python's repr() of a double (shortest round-trip text; json.dumps writes the same). */
void nte_py_repr(double x, char* buf, size_t size);
/** Python's repr() of the text s[0..n) (UTF-8; a byte that is not is shown as Python's
 *  surrogateescape reads it, \udcNN): in single quotes, or double ones when it holds a single
 *  quote and no double; backslashes and that quote escaped, \n, \r, \t, and what repr
 *  escapes as \xNN or \uNNNN (ASCII's controls, nte_units.h NTE_TEXT_UNPRINTABLE).  Limit:
 *  an unassigned code point, or one beyond U+FFFF that repr escapes, is shown as it is.  Cut
 *  to fit cap, quotes kept. */
void nte_py_repr_bytes(const char* s, size_t n, char* buf, size_t cap);
/** nte_py_repr_bytes of a terminated text. */
void nte_py_repr_text(const char* s, char* buf, size_t cap);
/** str.strip(): moves *s past the leading characters str.isspace names and returns the length
 *  of s[0..n) without them at either end. */
size_t nte_py_strip(const char** s, size_t n);

/** 1 when s[0..n) and the terminated `word` are equal with A-Z lowered and every other byte
 *  as it is (csvio.ascii_lower of both: the reader compares names and units so), else 0. */
int nte_py_ascii_same(const char* s, size_t n, const char* word);

/** 1 when s[0..n) is UTF-8 as Python's strict decoder reads it (no overlong form, no
 *  surrogate, nothing above U+10FFFF), else 0. */
int nte_py_utf8(const char* s, size_t n);

#endif /* NTE_NAME_VALUE_H */
