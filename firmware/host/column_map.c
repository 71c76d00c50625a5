/* --columns KEY=NAME,...; mirrors reference_py/tools/csvio.py ColumnMap.parse. */
#include "column_map.h"

#include "name_value.h"
#include "nte_units.h"

#include <stdio.h>
#include <string.h>

typedef struct column_key_t {
    const char* key;      /* the --columns key */
    const char* standard; /* the standard column it stands for */
} column_key_t;

static const column_key_t keys[NTE_COLUMN_KEY_COUNT] = NTE_COLUMN_KEYS;
static const char* const required[NTE_COLUMN_KEY_REQUIRED_COUNT] = NTE_COLUMN_KEYS_REQUIRED;

static int key_index(const char* key)
{
    for (int i = 0; i < NTE_COLUMN_KEY_COUNT; i++) {
        if (strcmp(keys[i].key, key) == 0) {
            return i;
        }
    }
    return -1;
}

/* The field of `c` that holds the column standing for `standard`. */
static char* field(nte_columns_t* c, const char* standard)
{
    return (strcmp(standard, "t_s") == 0)        ? c->t
           : (strcmp(standard, "depth_mm") == 0) ? c->depth
           : (strcmp(standard, "force_n") == 0)  ? c->force
                                                 : c->velocity;
}

/* The refusal "--columns TEXT: " + why. */
static int refuse(const char* text, const char* why, char* msg, size_t cap)
{
    (void)snprintf(msg, cap, "--columns %s: %s", text, why);
    return -1;
}

int nte_column_map_parse(const char* text, const int force_optional, nte_columns_t* c, char* msg,
                         size_t cap)
{
    static nte_nv_t items[NTE_NV_MAX];
    const char* given[NTE_COLUMN_KEY_COUNT] = {NULL};
    char why[(6U * NTE_NV_TEXT) + 128U];
    char a[(2U * NTE_NV_TEXT) + 8U];
    char b[(2U * NTE_NV_TEXT) + 8U];
    const size_t n = nte_nv_split(text, items, NTE_NV_MAX);
    for (size_t i = 0U; i < n; i++) {
        const nte_nv_t* it = &items[i];
        if ((it->has_eq == 0) || (it->name[0] == '\0')) {
            nte_py_repr_text(it->item, a, sizeof a);
            (void)snprintf(why, sizeof why,
                           "%s is not KEY=NAME (expected t=NAME,depth=NAME,"
                           "force=NAME[,velocity=NAME])",
                           a);
            return refuse(text, why, msg, cap);
        }
        const int k = key_index(it->name);
        nte_py_repr_text(it->name, a, sizeof a);
        if (k < 0) {
            size_t o = (size_t)snprintf(why, sizeof why, "unknown key %s (keys: ", a);
            for (int j = 0; (j < NTE_COLUMN_KEY_COUNT) && (o < sizeof why); j++) {
                o += (size_t)snprintf(why + o, sizeof why - o, "%s%s", (j > 0) ? ", " : "",
                                      keys[j].key);
            }
            if (o < sizeof why) {
                (void)snprintf(why + o, sizeof why - o, ")");
            }
            return refuse(text, why, msg, cap);
        }
        if (given[k] != NULL) {
            (void)snprintf(why, sizeof why, "key %s given twice", a);
            return refuse(text, why, msg, cap);
        }
        if (it->value[0] == '\0') {
            (void)snprintf(why, sizeof why, "key %s names no column", a);
            return refuse(text, why, msg, cap);
        }
        for (int j = 0; j < NTE_COLUMN_KEY_COUNT; j++) { /* at most one: names are unique */
            if ((given[j] != NULL) && (strcmp(given[j], it->value) == 0)) {
                char twin[(2U * NTE_NV_TEXT) + 8U];
                nte_py_repr_text(it->value, b, sizeof b);
                nte_py_repr_text(keys[j].key, twin, sizeof twin);
                (void)snprintf(why, sizeof why, "column %s given for both %s and %s", b, twin, a);
                return refuse(text, why, msg, cap);
            }
        }
        given[k] = it->value;
    }
    const int force = key_index("force");
    if ((force_optional != 0) && (given[force] == NULL)) {
        given[force] = keys[force].standard; /* --predict-only reads no force */
    }
    for (size_t r = 0U; r < NTE_COLUMN_KEY_REQUIRED_COUNT; r++) {
        if (given[key_index(required[r])] == NULL) {
            size_t o = (size_t)snprintf(why, sizeof why, "key '%s' missing (", required[r]);
            for (size_t j = 0U; (j < NTE_COLUMN_KEY_REQUIRED_COUNT) && (o < sizeof why); j++) {
                o += (size_t)snprintf(why + o, sizeof why - o, "%s%s", (j > 0U) ? ", " : "",
                                      required[j]);
            }
            if (o < sizeof why) {
                (void)snprintf(why + o, sizeof why - o, " are required, velocity is optional)");
            }
            return refuse(text, why, msg, cap);
        }
    }
    (void)memset(c, 0, sizeof *c);
    for (int j = 0; j < NTE_COLUMN_KEY_COUNT; j++) {
        char* f = field(c, keys[j].standard);
        (void)snprintf(f, NTE_COLUMN_NAME_MAX, "%s", (given[j] != NULL) ? given[j] : "");
    }
    c->velocity_required = c->velocity[0] != '\0';
    c->mapped = 1;
    return 0;
}
