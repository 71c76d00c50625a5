/*
 * nte_settings_file.h -- a configuration file (--config FILE, nte_config_file.h) as the Setting
 * items a transfer of it carries (firmware/can/nte.dbc Setting; nte_node.h SETTINGS).
 *
 * nte-node --config writes these items into its configuration with nte_node_setting_apply, the
 * function the node runs for each Setting frame, so a file read at start and the same file sent
 * over the bus configure the node alike, bit for bit.  The bench's sender builds the same list:
 * host_bench/settings_file.py, its twin (same items, same order, same float32 values; a test
 * compares the two).
 */
#ifndef NTE_SETTINGS_FILE_H
#define NTE_SETTINGS_FILE_H

#include <stddef.h>

#include "nte_config_file.h"
#include "nte_frames.h"

/** Most value items a file gives: model, seven parameters, r_n2, surface, delta, two time
 *  constants, branches, two switches, two strengths, the set count and five per set. */
#define NTE_SETTINGS_FILE_MAX (19u + (5u * NTE_FILE_LAYER_SETS))

/** The value items of `fc` into out[] (capacity NTE_SETTINGS_FILE_MAX), in item order, each
 *  key the file gave once; values rounded to float32 as the Setting frame carries them.
 *  Returns the count. */
size_t nte_settings_file_items(const nte_file_config_t* fc, nte_frames_setting_t* out);

#endif /* NTE_SETTINGS_FILE_H */
