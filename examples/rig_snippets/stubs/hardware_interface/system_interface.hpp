// The ros2_control declarations examples/rig_snippets/ros2_control_read.cpp
// uses, so CI compiles it against include/zwidth.h without ROS 2.
#pragma once
#include <cstddef>
namespace rclcpp {
struct Time {};
struct Duration {};
} // namespace rclcpp
namespace hardware_interface {
enum class return_type { OK, ERROR };
class SystemInterface {
  public:
    virtual ~SystemInterface() {}
    virtual return_type read(const rclcpp::Time &time, const rclcpp::Duration &period) = 0;
};
} // namespace hardware_interface
