/* A Simulink C Function block (or a QuaRC model) calling zwidth: the
 * block's Start Code calls zw_block_start, its Output Code
 * zw_block_output, with a DWork of 1024 uint64 (ZW_ESTIMATOR_WORDS) as
 * the estimator's state. */
#include <stdint.h>

#include "zwidth.h"

int zw_block_start(uint64_t *dwork, const char *spec, double ts, double encoder_m) {
    zw_error err;
    return zw_init_json((zw_estimator *)dwork, spec, 1.0 / ts, encoder_m, &err);
}

double zw_block_output(uint64_t *dwork, double position_m) {
    double v = 0.0;
    zw_step((zw_estimator *)dwork, position_m, &v);
    return v;
}
