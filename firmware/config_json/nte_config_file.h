/*
 * The estimator configuration file (--config FILE, schema nte-estimator-config/1) for the host
 * programs and the Linux port: the C twin of reference_py/tools/estconfig.py, same rules in the
 * same order, same one-line messages (tests/python/test_config_loop.py compares them over a
 * table of bad files).  Reads JSON with cJSON (Debian libcjson-dev): never linked into the
 * firmware library, which depends on libc alone.
 */
#ifndef NTE_CONFIG_FILE_H
#define NTE_CONFIG_FILE_H

#include <stddef.h>

/** What a configuration file sets; each has_* says whether the file gave the value. */
typedef struct nte_file_config_t {
    int model;          /**< 1, 2 or 3 */
    double params[7];   /**< sigma0, sigma1, sigma2, f1, f2, alpha, beta: the new nominal */
    int has_r_n2;
    double r_n2;
    int has_surface;    /**< a known surface (a number) */
    double surface_mm;
    int surface_list;   /**< per-trial surfaces (the workflow's): find it from the force */
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
    int has_strengths;  /**< g[0] g_fast, g[1] g_slow: nominal strengths */
    double g[2];
} nte_file_config_t;

/**
 * Read and check path into *out.  Returns 0, or -1 with the message ("FILE: key 'KEY':
 * reason" or "FILE: reason") in msg.
 */
int nte_config_file_read(const char* path, nte_file_config_t* out, char* msg, size_t cap);

#endif /* NTE_CONFIG_FILE_H */
