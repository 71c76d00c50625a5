/*
 * The estimator configuration file (--config FILE, schema nte-estimator-config/1) for the host
 * programs and the Linux port: the C twin of reference_py/tools/estconfig.py, same rules in the
 * same order, same one-line messages (tests/python/test_config_loop.py compares them over a
 * table of bad files).  Reads JSON with cJSON (Debian libcjson-dev): never linked into the
 * firmware library, which depends on libc alone.
 */
#ifndef NTE_CONFIG_FILE_H
#define NTE_CONFIG_FILE_H

#include "nte.h"

#include <stddef.h>

/** Layer sets a file may give: the estimator's capacity, NTE_LAYER_SETS_MAX (a program built
 *  with fewer, as the board image is, cannot take the reader). */
#define NTE_FILE_LAYER_SETS 3
#if NTE_FILE_LAYER_SETS != NTE_LAYER_SETS_MAX
#error "the configuration file's layer sets need NTE_LAYER_SETS_MAX = 3"
#endif

/** What a configuration file sets; each has_* says whether the file gave the value. */
typedef struct nte_file_config_t {
    int model;        /**< 1, 2 or 3 */
    double params[7]; /**< sigma0, sigma1, sigma2, f1, f2, alpha, beta: the new nominal */
    int has_r_n2;
    double r_n2;
    int has_surface; /**< a known surface (a number) */
    double surface_mm;
    int surface_list; /**< per-trial surfaces (the workflow's): find it from the force */
    int has_presliding;
    double presliding_mm;
    int has_tau_fast;
    double tau_fast_s;
    int has_tau_slow;
    double tau_slow_s;
    int has_relax_branches;
    int relax_branches;
    int has_relaxation;
    int relaxation;
    int has_direction_memory;
    int direction_memory;
    int has_strengths; /**< g[0] g_fast, g[1] g_slow: nominal strengths */
    double g[2];
    int layer_sets; /**< model3.layer_sets given: the count, 0..NTE_FILE_LAYER_SETS */
    double layer_start_mm[NTE_FILE_LAYER_SETS];  /**< each set's start, mm below the surface */
    double layer_values[NTE_FILE_LAYER_SETS][4]; /**< sigma0, f1, beta, sigma2 */
} nte_file_config_t;

/**
 * Read and check path into *out.  Returns 0, or -1 with the message ("FILE: key 'KEY':
 * reason" or "FILE: reason") in msg.
 */
int nte_config_file_read(const char* path, nte_file_config_t* out, char* msg, size_t cap);

/** The file's layer sets into a Model III configuration (in the including program's
 *  nte_real_t: the reader itself is built in double). */
static inline void nte_config_file_layer_sets(const nte_file_config_t* fc, nte_config_t* cfg)
{
    cfg->layer_sets = (uint32_t)fc->layer_sets;
    for (int k = 0; k < fc->layer_sets; k++) {
        cfg->layer_set[k].start_mm = (nte_real_t)fc->layer_start_mm[k];
        for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
            cfg->layer_set[k].values[j] = (nte_real_t)fc->layer_values[k][j];
        }
    }
}

#endif /* NTE_CONFIG_FILE_H */
