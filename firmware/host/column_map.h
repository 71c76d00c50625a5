/*
 * --columns t=NAME,depth=NAME,force=NAME[,velocity=NAME] of nte-run: a logger's own column
 * names (the C twin of reference_py/tools/csvio.py ColumnMap.parse, its checks and messages).
 * Host only.
 */
#ifndef NTE_COLUMN_MAP_H
#define NTE_COLUMN_MAP_H

#include "csv_in.h"

#include <stddef.h>

/**
 * Parse the map `text` into columns: the keys of nte_units.h's NTE_COLUMN_KEYS, each once,
 * each naming a column of its own; t, depth and force required; without velocity= the
 * velocity is computed from the depth (never read), with it the column must be there.
 * `force_optional` (--predict-only, which reads no force): force= may be left out, the
 * standard name then stands (absent or ignored).
 * Returns 0, or -1 with "--columns TEXT: reason" in msg.
 */
int nte_column_map_parse(const char* text, int force_optional, nte_columns_t* columns, char* msg,
                         size_t cap);

#endif /* NTE_COLUMN_MAP_H */
