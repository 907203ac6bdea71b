// ros2_control: a hardware interface's read() steps zwidth's estimator on
// each joint's encoder and exports its velocity as the velocity state.
#include <vector>

#include "hardware_interface/system_interface.hpp"
#include "zwidth.h"

class ZwidthHaptic : public hardware_interface::SystemInterface {
  public:
    hardware_interface::return_type read(const rclcpp::Time &, const rclcpp::Duration &) override {
        for (size_t j = 0; j < est_.size(); j++) {
            hw_positions_[j] = encoder_position(j); // m
            zw_step(&est_[j], hw_positions_[j], &hw_velocities_[j]);
        }
        return hardware_interface::return_type::OK;
    }

  private:
    double encoder_position(size_t joint);
    std::vector<zw_estimator> est_; // filled by zw_init_json in on_init()
    std::vector<double> hw_positions_, hw_velocities_;
};
