// CHAI3D: a device class whose velocity is zwidth's estimator, stepped
// where the servo loop reads the encoder (getPosition), instead of the
// SDK's wall-clock-windowed difference.
#include <stdexcept>

#include "chai3d.h"
#include "zwidth.h"

class cZwidthDevice : public chai3d::cMyCustomDevice {
  public:
    // spec: the API's JSON estimator spec; rate_hz: the servo rate (Hz);
    // encoder_m: the encoder step (m).
    cZwidthDevice(const char *spec, double rate_hz, double encoder_m) {
        zw_error err;
        for (int i = 0; i < 3; i++)
            if (zw_init_json(&m_est[i], spec, rate_hz, encoder_m, &err) != ZW_OK)
                throw std::invalid_argument(err.message);
    }
    // Once per servo tick: the position, and the velocity from it.
    bool getPosition(chai3d::cVector3d &a_position) override {
        if (!cMyCustomDevice::getPosition(a_position)) return false;
        for (int i = 0; i < 3; i++) zw_step(&m_est[i], a_position(i), &m_velocity[i]);
        return true;
    }
    bool getLinearVelocity(chai3d::cVector3d &a_linearVelocity) override {
        a_linearVelocity.set(m_velocity[0], m_velocity[1], m_velocity[2]);
        return true;
    }

  private:
    zw_estimator m_est[3]; // 3 × 8 KiB inside the device object: no malloc
    double m_velocity[3] = {0.0, 0.0, 0.0};
};
