#include "proprio/rig_plan/joint_ranges.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace proprio::rig_plan {
namespace {

using Type = DeviceModule::Type;

double angle_between(const Vec3& a, const Vec3& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }

// The centre of a set of unit vectors that minimises the largest angle to
// them (Badoiu-Clarkson iterations on the sphere, from the normalised mean).
Vec3 minimax_centre(const std::vector<Vec3>& u) {
  Vec3 c = Vec3::Zero();
  for (const auto& v : u) c += v;
  c = c.norm() > 1e-9 ? c.normalized() : u.front();
  for (int k = 1; k <= 200; ++k) {
    std::size_t far = 0;
    double worst = -1.0;
    for (std::size_t i = 0; i < u.size(); ++i) {
      const double a = angle_between(c, u[i]);
      if (a > worst) {
        worst = a;
        far = i;
      }
    }
    const Vec3 next = c + (u[far] - c) / static_cast<double>(k + 1);
    if (next.norm() < 1e-9) break;
    c = next.normalized();
  }
  return c;
}

const rig_device::SplitterKind* kind_of(const Plan& plan, const std::string& name) {
  for (const auto& k : plan.kit.splitter_kinds)
    if (k.name == name) return &k;
  return nullptr;
}

}  // namespace

double shaft_angle_rad(const Quat& q_in_out) { return angle_between(Vec3::UnitZ(), q_in_out * Vec3::UnitZ()); }

JointRangeReport joint_range_report(const Plan& plan) {
  JointRangeReport r;
  r.limit_rad = plan.kit.joint.bend_limit_rad;
  for (std::size_t m = 0; m < plan.modules.size(); ++m) {
    if (plan.modules[m].type != Type::joint) continue;
    JointRangeReport::Joint j;
    j.module = static_cast<int>(m);
    j.rest_shaft_rad = shaft_angle_rad(plan.modules[m].q_in_out_rest);
    j.max_shaft_rad = j.rest_shaft_rad;
    for (const auto& pose : plan.device_poses) {
      if (m >= pose.size()) continue;
      const double a = shaft_angle_rad(pose[m]);
      j.max_shaft_rad = std::max(j.max_shaft_rad, a);
      if (a > r.limit_rad) ++j.samples_past_stop;
    }
    if (j.rest_shaft_rad > r.limit_rad || j.samples_past_stop > 0) ++r.joints_past_stop;
    r.joints.push_back(j);
  }
  return r;
}

std::string JointRangeReport::describe(const Plan& plan, const Skeleton* skeleton) const {
  std::ostringstream s;
  const double deg = 180.0 / M_PI;
  for (const auto& j : joints) {
    if (j.rest_shaft_rad <= limit_rad && j.samples_past_stop == 0) continue;
    s << "module " << (j.module + 1) << " (joint";
    const int node = plan.modules[static_cast<std::size_t>(j.module)].rig_node;
    if (skeleton && node >= 0 && static_cast<std::size_t>(node) < skeleton->size())
      s << " driving '" << skeleton->names[static_cast<std::size_t>(node)] << "'";
    else if (node >= 0)
      s << " driving rig node " << node;
    s << "): " << j.samples_past_stop << " of " << plan.device_poses.size()
      << " sample poses need its shafts bent past the " << std::lround(limit_rad * deg) << " deg stop (up to "
      << std::lround(j.max_shaft_rad * deg) << " deg)";
    if (j.rest_shaft_rad > limit_rad) s << ", its rest setting too";
    s << "; the device reaches them only partly there\n";
  }
  return s.str();
}

int center_joint_ranges(Plan& plan, double margin_rad) {
  const std::size_t M = plan.modules.size();
  const double limit = plan.kit.joint.bend_limit_rad;
  // C_in[m]: how module m's inlet frame turned (in its own coordinates) when a
  // module above it changed its rest setting.
  std::vector<Quat> C_in(M, Quat::Identity());
  // Per module, the turn of what is plugged into each outlet.
  std::vector<std::vector<Quat>> C_out(M);
  int moved = 0;
  for (std::size_t m = 0; m < M; ++m) {
    DeviceModule& mod = plan.modules[m];
    if (mod.parent_module >= 0) {
      const auto& outs = C_out[static_cast<std::size_t>(mod.parent_module)];
      const auto o = static_cast<std::size_t>(std::max(0, mod.parent_outlet));
      C_in[m] = o < outs.size() ? outs[o] : Quat::Identity();
    }
    const Quat C = C_in[m];
    if (mod.type == Type::splitter) {
      // Rigid: each outlet turns as the inlet did, seen from the outlet.
      const auto* kind = kind_of(plan, mod.kind);
      const std::size_t n = kind ? kind->valence() : 0;
      C_out[m].assign(n, Quat::Identity());
      for (std::size_t o = 0; o < n; ++o) {
        const Quat F = (mod.q_in_out_rest * kind->q_inlet_outlet[o]).normalized();
        C_out[m][o] = (F.conjugate() * C * F).normalized();
      }
      continue;
    }
    // A joint: its inlet turned by C; keep its outlet (and everything after
    // it) where it was, and its samples mapping to the same rig rotations.
    mod.q_parent_inlet = (mod.q_parent_inlet * C).normalized();
    mod.q_in_out_rest = (C.conjugate() * mod.q_in_out_rest).normalized();
    for (auto& pose : plan.device_poses)
      if (m < pose.size()) pose[m] = (C.conjugate() * pose[m]).normalized();
    // Its own range.
    double worst = shaft_angle_rad(mod.q_in_out_rest);
    std::vector<Vec3> u{Vec3::UnitZ()};
    for (const auto& pose : plan.device_poses) {
      if (m >= pose.size()) continue;
      worst = std::max(worst, shaft_angle_rad(pose[m]));
      // Delta_s = pose * rest^-1; the outlet direction v = R z reaches
      // angle(Delta_s^-1 z, v) in sample s.
      const Quat delta = (pose[m] * mod.q_in_out_rest.conjugate()).normalized();
      u.push_back(delta.conjugate() * Vec3::UnitZ());
    }
    Quat turn = Quat::Identity();  // C_out of this joint, in its outlet's coordinates
    if (worst > limit - margin_rad) {
      const Vec3 v_old = mod.q_in_out_rest * Vec3::UnitZ();
      const Vec3 v_new = minimax_centre(u);
      const Quat R_new = (Quat::FromTwoVectors(v_old, v_new) * mod.q_in_out_rest).normalized();
      // Only if it helps: the largest shaft angle over rest and samples.
      double worst_new = shaft_angle_rad(R_new);
      for (const auto& pose : plan.device_poses) {
        if (m >= pose.size()) continue;
        const Quat delta = (pose[m] * mod.q_in_out_rest.conjugate()).normalized();
        worst_new = std::max(worst_new, shaft_angle_rad(delta * R_new));
      }
      if (worst_new < worst - 1e-6) {
        turn = (mod.q_in_out_rest.conjugate() * R_new).normalized();
        for (auto& pose : plan.device_poses)
          if (m < pose.size()) pose[m] = (pose[m] * turn).normalized();
        mod.q_in_out_rest = R_new;
        ++moved;
      }
    }
    C_out[m].assign(1, turn);
  }
  return moved;
}

}  // namespace proprio::rig_plan
