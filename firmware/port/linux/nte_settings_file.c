/* nte_settings_file.c -- see nte_settings_file.h. */
#include "nte_settings_file.h"

static void put(nte_frames_setting_t* out, size_t* n, int item, double value)
{
    out[*n].item = (uint8_t)item;
    out[*n].value = (float)value;
    (*n)++;
}

size_t nte_settings_file_items(const nte_file_config_t* fc, nte_frames_setting_t* out)
{
    size_t n = 0u;
    put(out, &n, NTE_FRAMES_SETTING_MODEL, (double)fc->model);
    for (int j = 0; j < 7; j++) {
        put(out, &n, NTE_FRAMES_SETTING_PARAM0 + j, fc->params[j]);
    }
    if (fc->has_strengths) {
        put(out, &n, NTE_FRAMES_SETTING_PARAM0 + 7, fc->g[0]);
        put(out, &n, NTE_FRAMES_SETTING_PARAM0 + 8, fc->g[1]);
    }
    if (fc->has_presliding) {
        put(out, &n, NTE_FRAMES_SETTING_PARAM0 + 9, fc->presliding_mm);
    }
    if (fc->has_r_n2) {
        put(out, &n, NTE_FRAMES_SETTING_R_N2, fc->r_n2);
    }
    if (fc->has_surface) { /* a single known surface; a per-trial list: found from the force */
        put(out, &n, NTE_FRAMES_SETTING_SURFACE_MM, fc->surface_mm);
    }
    if (fc->has_tau_fast) {
        put(out, &n, NTE_FRAMES_SETTING_TAU_FAST_S, fc->tau_fast_s);
    }
    if (fc->has_tau_slow) {
        put(out, &n, NTE_FRAMES_SETTING_TAU_SLOW_S, fc->tau_slow_s);
    }
    if (fc->has_relax_branches) {
        put(out, &n, NTE_FRAMES_SETTING_RELAX_BRANCHES, (double)fc->relax_branches);
    }
    if (fc->has_relaxation) {
        put(out, &n, NTE_FRAMES_SETTING_RELAXATION, (fc->relaxation != 0) ? 1.0 : 0.0);
    }
    if (fc->has_direction_memory) {
        put(out, &n, NTE_FRAMES_SETTING_DIRECTION_MEMORY, (fc->direction_memory != 0) ? 1.0 : 0.0);
    }
    if (fc->layer_sets > 0) {
        put(out, &n, NTE_FRAMES_SETTING_LAYER_SETS, (double)fc->layer_sets);
        for (int k = 0; k < fc->layer_sets; k++) {
            const int first = NTE_FRAMES_SETTING_LAYER0 + (NTE_FRAMES_SETTING_LAYER_FIELDS * k);
            put(out, &n, first, fc->layer_start_mm[k]);
            for (int j = 0; j < 4; j++) {
                put(out, &n, first + 1 + j, fc->layer_values[k][j]);
            }
        }
    }
    return n;
}
