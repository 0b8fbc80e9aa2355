// force_vector: a device with its own force control (a force-controlled
// platform, a commercial fingertip device with a force API). The model is the
// clamp; MotorAngles carries the force components, in newtons, unchanged.
#include <cstdio>

#include "proprio/haptics/device_model.hpp"

namespace proprio::haptics {

namespace {

class ForceVectorDevice final : public FingertipDeviceModel {
 public:
  ForceVectorDevice(ForceVectorParams p, DeviceLimits limits) : p_(std::move(p)), limits_(limits) {}

  std::string_view kind() const noexcept override { return "force_vector"; }
  std::size_t motor_count() const noexcept override { return 3; }
  const DeviceLimits& limits() const noexcept override { return limits_; }
  ForceAxes axes() const noexcept override { return ForceAxes{true, true}; }
  MotorSpec motor_spec() const noexcept override { return MotorSpec{}; }

  FingertipForce renderable(const FingertipForce& desired) const noexcept override {
    return clamp_to_limits(desired, limits_, axes());
  }
  MotorAngles inverse(const FingertipForce& force) const noexcept override {
    const FingertipForce f = renderable(force);
    MotorAngles q;
    q.rad = {f.normal_n, f.shear_x_n, f.shear_z_n};
    return q;
  }
  // The identity: what the device does with a command is its own business,
  // and round trips need no clamp here because inverse() clamped.
  FingertipForce forward(const MotorAngles& q) const noexcept override {
    return FingertipForce{q.rad[0], q.rad[1], q.rad[2]};
  }
  // No shafts to load: an emulator of such a device reflects the force.
  std::array<double, kMaxDeviceMotors> load_torques(const MotorAngles&) const noexcept override { return {}; }
  MotorAngles rest() const noexcept override { return {}; }

  std::string describe() const override {
    return "force_vector" + (p_.name.empty() ? std::string() : " '" + p_.name + "'") + ": " + p_.describe() +
           "; limits " + limits_.describe();
  }

 private:
  ForceVectorParams p_;
  DeviceLimits limits_;
};

}  // namespace

std::string ForceVectorParams::describe() const {
  return "3 channels (normal, shear_x, shear_z in N; the device controls force itself), forward = inverse = identity "
         "after the clamp";
}

Result<std::unique_ptr<FingertipDeviceModel>> make_force_vector_device(ForceVectorParams params,
                                                                       DeviceLimits limits) {
  if (auto st = limits.validate(); !st) return st.error();
  return std::unique_ptr<FingertipDeviceModel>(std::make_unique<ForceVectorDevice>(std::move(params), limits));
}

}  // namespace proprio::haptics
