/* The few CHAI3D declarations examples/rig_snippets/chai3d_device.cpp
 * uses, so CI compiles it against include/zwidth.h without the SDK. */
#pragma once
namespace chai3d {
struct cVector3d {
    double v[3];
    double &operator()(int i) { return v[i]; }
    void set(double x, double y, double z) { v[0] = x; v[1] = y; v[2] = z; }
};
class cGenericHapticDevice {
  public:
    virtual ~cGenericHapticDevice() {}
    virtual bool getPosition(cVector3d &a_position);
    virtual bool getLinearVelocity(cVector3d &a_linearVelocity);
};
class cMyCustomDevice : public cGenericHapticDevice {
  public:
    bool getPosition(cVector3d &a_position) override;
};
} // namespace chai3d
