/*
 * The estimator configuration file (--config FILE, schema nte-estimator-config/1) for the host
 * programs: the C twin of reference_py/tools/estconfig.py, same rules in the same order, same
 * one-line messages (tests/python/test_config_loop.py compares them over a table of bad
 * files).  Reads JSON with cJSON (Debian libcjson-dev): host programs only, the firmware
 * library depends on libc alone.
 */
#ifndef NTE_HOST_CONFIG_FILE_H
#define NTE_HOST_CONFIG_FILE_H

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

/** What --export-config writes (reference_py/tools/estimate.py export_config). */
typedef struct nte_export_t {
    const char* source;  /**< "nte-run" */
    int model;
    double params[7];    /**< the final estimates, the fixed ones at their nominal */
    double sd[7];        /**< 0 for the fixed ones */
    double r_n2;
    size_t samples;
    /* Model III */
    int direction_memory;
    double presliding_mm;
    int relaxation;
    int relax_branches;
    double tau_fast_s;
    double tau_slow_s;
    size_t n_g;          /**< strengths identified (the branches in use) */
    const char* g_name[2];
    double g[2];
    double g_sd[2];
    /* the contact front end */
    int contact;
    double surface_mm;   /**< NaN: not found (null) */
    double tare_n;
} nte_export_t;

/**
 * The configuration as JSON text, byte for byte what the reference's json.dumps(..., indent=2)
 * writes for the same values (floats in Python's shortest round-trip form).  Returns the
 * length, or -1 when cap is too small.
 */
int nte_config_file_export_text(const nte_export_t* e, char* buf, size_t cap);

#endif /* NTE_HOST_CONFIG_FILE_H */
