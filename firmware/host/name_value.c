/* NAME=VALUE lists and Python's repr() of a text, for --start and --columns. */
#include "name_value.h"

#include <stdio.h>
#include <string.h>

/* s[0..n) stripped of ASCII whitespace at both ends (str.strip), into buf. */
static void stripped(const char* s, size_t n, char* buf, size_t cap)
{
    while ((n > 0U) && (strchr(" \t\r\n\v\f", s[0]) != NULL)) {
        s++;
        n--;
    }
    while ((n > 0U) && (strchr(" \t\r\n\v\f", s[n - 1U]) != NULL)) {
        n--;
    }
    (void)snprintf(buf, cap, "%.*s", (int)n, s);
}

size_t nte_nv_split(const char* text, nte_nv_t* items, size_t max)
{
    size_t count = 0U;
    const char* p = text;
    while (count < max) {
        const char* comma = strchr(p, ',');
        const size_t n = (comma != NULL) ? (size_t)(comma - p) : strlen(p);
        nte_nv_t* it = &items[count++];
        const char* eq = memchr(p, '=', n);
        stripped(p, n, it->item, sizeof it->item);
        stripped(p, (eq != NULL) ? (size_t)(eq - p) : n, it->name, sizeof it->name);
        if (eq != NULL) {
            stripped(eq + 1, n - (size_t)(eq + 1 - p), it->value, sizeof it->value);
        } else {
            it->value[0] = '\0';
        }
        it->has_eq = eq != NULL;
        if (comma == NULL) {
            break;
        }
        p = comma + 1;
    }
    return count;
}

void nte_py_repr_text(const char* s, char* buf, size_t cap)
{
    const char q = ((strchr(s, '\'') != NULL) && (strchr(s, '"') == NULL)) ? '"' : '\'';
    size_t o = 0U;
    buf[o++] = q;
    for (; (*s != '\0') && ((o + 6U) < cap); s++) {
        const unsigned char c = (unsigned char)*s;
        if ((c == (unsigned char)q) || (c == '\\')) {
            buf[o++] = '\\';
            buf[o++] = (char)c;
        } else if ((c == '\n') || (c == '\r') || (c == '\t')) {
            buf[o++] = '\\';
            buf[o++] = (char)((c == '\n') ? 'n' : ((c == '\r') ? 'r' : 't'));
        } else if ((c < 0x20U) || (c == 0x7fU)) {
            (void)snprintf(&buf[o], cap - o, "\\x%02x", (unsigned)c);
            o += 4U;
        } else {
            buf[o++] = (char)c;
        }
    }
    buf[o++] = q;
    buf[o] = '\0';
}
