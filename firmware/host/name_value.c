/* Python's text rules for the host programs' messages, and NAME=VALUE lists as Python splits
 * them (--start, --columns). */
#include "name_value.h"

#include "nte_units.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- Python's text rules ---------------------------------------------------------------- */

/* The code point that starts s[0..n) and its length in bytes (*len), strict UTF-8 as Python
 * decodes it; a byte that starts no valid sequence is one character, U+DC80..U+DCFF, as
 * Python's surrogateescape reads it (command-line arguments). */
static unsigned long utf8_at(const char* text, const size_t n, size_t* len)
{
    const unsigned char* s = (const unsigned char*)text;
    const unsigned long b = s[0];
    *len = 1U;
    if (b < 0x80UL) {
        return b;
    }
    /* the lead byte: how many continuation bytes follow, and the range of the first one */
    size_t need = 1U;
    unsigned long lo = 0x80UL;
    unsigned long hi = 0xbfUL;
    if ((b >= 0xe0UL) && (b <= 0xefUL)) {
        need = 2U;
        lo = (b == 0xe0UL) ? 0xa0UL : lo; /* no overlong form */
        hi = (b == 0xedUL) ? 0x9fUL : hi; /* no surrogate */
    } else if ((b >= 0xf0UL) && (b <= 0xf4UL)) {
        need = 3U;
        lo = (b == 0xf0UL) ? 0x90UL : lo;
        hi = (b == 0xf4UL) ? 0x8fUL : hi; /* nothing above U+10FFFF */
    } else if ((b < 0xc2UL) || (b > 0xdfUL)) {
        return 0xdc00UL + b; /* starts no sequence */
    } else {
        /* two bytes */
    }
    unsigned long cp = b & (0x3fUL >> need);
    for (size_t i = 1U; i <= need; i++) {
        const unsigned long c = (i < n) ? s[i] : 0UL;
        if ((c < ((i == 1U) ? lo : 0x80UL)) || (c > ((i == 1U) ? hi : 0xbfUL))) {
            return 0xdc00UL + b;
        }
        cp = (cp << 6U) | (c & 0x3fUL);
    }
    *len = need + 1U;
    return cp;
}

int nte_py_utf8(const char* s, const size_t n)
{
    for (size_t i = 0U; i < n;) {
        size_t len = 0U;
        const unsigned long cp = utf8_at(s + i, n - i, &len);
        if ((cp >= 0xdc80UL) && (cp <= 0xdcffUL)) {
            return 0;
        }
        i += len;
    }
    return 1;
}

/* What Python's repr escapes (str.isprintable is false): ASCII's controls, the runs of
 * nte_units.h above U+007F, and the surrogateescape's stand-ins of bytes that are not UTF-8. */
static int py_unprintable(const unsigned long cp)
{
    static const unsigned long runs[NTE_TEXT_UNPRINTABLE_COUNT][2] = NTE_TEXT_UNPRINTABLE;
    if ((cp < 0x20UL) || (cp == 0x7fUL) || ((cp >= 0xd800UL) && (cp <= 0xdfffUL))) {
        return 1;
    }
    for (size_t i = 0U; i < NTE_TEXT_UNPRINTABLE_COUNT; i++) {
        if ((cp >= runs[i][0]) && (cp <= runs[i][1])) {
            return 1;
        }
    }
    return 0;
}

static int py_space(const unsigned long cp)
{
    static const unsigned long spaces[NTE_TEXT_SPACE_COUNT] = NTE_TEXT_SPACES;
    for (size_t i = 0U; i < NTE_TEXT_SPACE_COUNT; i++) {
        if (spaces[i] == cp) {
            return 1;
        }
    }
    return 0;
}

size_t nte_py_strip(const char** s, size_t n)
{
    size_t len = 0U;
    while ((n > 0U) && py_space(utf8_at(*s, n, &len))) {
        *s += len;
        n -= len;
    }
    while (n > 0U) {
        size_t k = n - 1U;
        while ((k > 0U) && ((((unsigned char)(*s)[k]) & 0xc0U) == 0x80U)) {
            k--;
        }
        const unsigned long cp = utf8_at(*s + k, n - k, &len);
        if (((k + len) != n) || !py_space(cp)) {
            break;
        }
        n = k;
    }
    return n;
}

void nte_py_repr_bytes(const char* s, const size_t n, char* buf, const size_t cap)
{
    const char q = ((memchr(s, '\'', n) != NULL) && (memchr(s, '"', n) == NULL)) ? '"' : '\'';
    size_t o = 0U;
    buf[o++] = q;
    for (size_t i = 0U; i < n;) {
        size_t len = 0U;
        const unsigned long cp = utf8_at(s + i, n - i, &len);
        char piece[24];
        if ((cp == (unsigned long)q) || (cp == '\\')) {
            (void)snprintf(piece, sizeof piece, "\\%c", (char)cp);
        } else if ((cp == '\n') || (cp == '\r') || (cp == '\t')) {
            (void)snprintf(piece, sizeof piece, "\\%c",
                           (cp == '\n')   ? 'n'
                           : (cp == '\r') ? 'r'
                                          : 't');
        } else if (py_unprintable(cp)) {
            (void)snprintf(piece, sizeof piece, (cp < 0x100UL) ? "\\x%02lx" : "\\u%04lx", cp);
        } else {
            (void)snprintf(piece, sizeof piece, "%.*s", (int)len, s + i);
        }
        const size_t pl = strlen(piece);
        if ((o + pl + 2U) > cap) {
            break;
        }
        (void)memcpy(buf + o, piece, pl);
        o += pl;
        i += len;
    }
    buf[o++] = q;
    buf[o] = '\0';
}

void nte_py_repr_text(const char* s, char* buf, const size_t cap)
{
    nte_py_repr_bytes(s, strlen(s), buf, cap);
}

void nte_py_repr(const double x, char* buf, const size_t size)
{
    if (!isfinite(x)) {
        (void)snprintf(buf, size, "%s", isnan(x) ? "nan" : ((x < 0.0) ? "-inf" : "inf"));
        return;
    }
    /* the fewest significant digits that read back as x, laid out as repr lays them out: with
     * an exponent below 1e-4 and from 1e16 on, else positional with at least one decimal */
    char e[32];
    int digits = 1;
    for (; digits < 17; digits++) {
        (void)snprintf(e, sizeof e, "%.*e", digits - 1, x);
        const double back = strtod(e, NULL);
        if (memcmp(&back, &x, sizeof back) == 0) {
            break;
        }
    }
    (void)snprintf(e, sizeof e, "%.*e", digits - 1, x);
    const int exp10 = atoi(strchr(e, 'e') + 1);
    const int decimals = digits - 1 - exp10;
    if ((exp10 < -4) || (exp10 >= 16)) {
        (void)snprintf(buf, size, "%s", e);
    } else if (decimals > 0) {
        (void)snprintf(buf, size, "%.*f", decimals, x);
    } else {
        (void)snprintf(buf, size, "%.0f.0", x);
    }
}

/* s[0..n) stripped at both ends (str.strip), into buf. */
static void stripped(const char* s, size_t n, char* buf, size_t cap)
{
    n = nte_py_strip(&s, n);
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

int nte_py_ascii_same(const char* s, const size_t n, const char* word)
{
    if (strlen(word) != n) {
        return 0;
    }
    for (size_t i = 0U; i < n; i++) {
        const int a = ((s[i] >= 'A') && (s[i] <= 'Z')) ? (s[i] + ('a' - 'A')) : s[i];
        const int b = ((word[i] >= 'A') && (word[i] <= 'Z')) ? (word[i] + ('a' - 'A')) : word[i];
        if (a != b) {
            return 0;
        }
    }
    return 1;
}
