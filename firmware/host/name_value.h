/*
 * A comma-separated NAME=VALUE list as the Python tools split one (--start, --columns): the
 * items at every ',', each partitioned at its first '=', every part stripped of whitespace
 * (str.split, str.partition, str.strip); and Python's repr() of a text, for the messages.
 * Host only.
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

/** Python's repr() of a text: in single quotes, or double ones when it holds a single quote
 *  and no double; backslashes and that quote escaped, control characters as \n, \r, \t,
 *  \xNN. */
void nte_py_repr_text(const char* s, char* buf, size_t cap);

#endif /* NTE_NAME_VALUE_H */
