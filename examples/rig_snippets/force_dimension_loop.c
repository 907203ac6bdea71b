/* A Force Dimension servo loop: zwidth's estimator instead of
 * dhdGetLinearVelocity, the wall F = -K x - B v for x > 0 on each axis. */
#include "dhdc.h"
#include "zwidth.h"

static zw_estimator est[3]; /* statics: no malloc in the loop */

int servo(const char *spec, double rate_hz, double encoder_m, double k, double b) {
    zw_error err;
    for (int i = 0; i < 3; i++)
        if (zw_init_json(&est[i], spec, rate_hz, encoder_m, &err) != ZW_OK) return -1;
    while (!dhdKbHit()) {
        double p[3], v[3], f[3];
        dhdGetPosition(&p[0], &p[1], &p[2]);
        for (int i = 0; i < 3; i++) {
            zw_step(&est[i], p[i], &v[i]); /* not dhdGetLinearVelocity */
            f[i] = p[i] > 0.0 ? -k * p[i] - b * v[i] : 0.0;
        }
        dhdSetForce(f[0], f[1], f[2]);
    }
    return 0;
}
