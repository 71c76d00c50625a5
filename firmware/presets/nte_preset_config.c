/* nte_preset_config.c -- see nte_preset_config.h. */
#include "nte_preset_config.h"

#include <stddef.h>

int nte_preset_nominal(nte_config_t* cfg, const double values[7])
{
    for (size_t j = 0U; j < 7U; j++) {
        cfg->nominal[j] = (nte_real_t)values[j];
    }
    const double kappa = (values[4] < 0.0) ? 1.0 : 0.0;
    const double excess = values[3] - (kappa * (-values[4]));
    if (!(excess > 0.0)) {
        return -1;
    }
    cfg->f1_excess = (nte_real_t)excess;
    return 0;
}
