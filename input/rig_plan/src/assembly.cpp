#include "proprio/rig_plan/assembly.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "proprio/core/file_io.hpp"
#include "proprio/rig_device/joint_kinematics.hpp"
#include "proprio/rig_plan/plan_io.hpp"

namespace proprio::rig_plan {

namespace assembly_detail {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

std::string deg(double rad) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(1) << rad * kDegPerRad;
  std::string s = out.str();
  return s == "-0.0" ? "0.0" : s;
}

std::string node_name(const Skeleton& skeleton, int node) {
  return "'" + printable(skeleton.names[static_cast<std::size_t>(node)], 60) + "'";
}

// The rotation about the inlet shaft (z) in q: the twist of a swing-twist split.
double turn_about_inlet_rad(const Quat& q) {
  return rig_device::wrap_angle_rad(2.0 * std::atan2(q.z(), q.w()));
}

std::string xml(const std::string& s) {
  std::string out;
  for (char c : printable(s, 80)) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

Status check(const RigInput& input, const Plan& plan) {
  if (Status s = input.skeleton.validate(); !s) return s.error().with_context("assembly instructions");
  if (Status s = validate_plan(plan, input.skeleton.size()); !s)
    return s.error().with_context("assembly instructions");
  return {};
}

std::string where(const Plan& plan, const DeviceModule& m) {
  if (m.parent_module < 0)
    return m.parent_outlet == 0 ? std::string("the base") : "port " + std::to_string(m.parent_outlet) + " of the base";
  const DeviceModule& p = plan.modules[static_cast<std::size_t>(m.parent_module)];
  if (p.type == DeviceModule::Type::joint) return "the outlet of " + module_label(plan, m.parent_module);
  return "outlet " + std::to_string(m.parent_outlet) + " of " + module_label(plan, m.parent_module);
}

}  // namespace
}  // namespace assembly_detail

Status AssemblyOptions::validate() const {
  const auto ok = [](double v) { return std::isfinite(v) && v >= 100.0 && v <= 10000.0; };
  if (!ok(view_width_px) || !ok(view_height_px))
    return make_error(Errc::invalid_argument, "assembly picture: each view must be 100..10000 px wide and high");
  return {};
}

std::string AssemblyOptions::describe() const {
  std::ostringstream out;
  out << "assembly picture: front and side views of " << view_width_px << " x " << view_height_px << " px"
      << (label_all_nodes ? ", every node named" : "");
  return out.str();
}

Result<std::string> assembly_text(const RigInput& input, const Plan& plan) {
  using assembly_detail::check;
  using assembly_detail::deg;
  using assembly_detail::node_name;
  using assembly_detail::turn_about_inlet_rad;
  using assembly_detail::where;
  if (Status s = check(input, plan); !s) return s.error();
  const Skeleton& sk = input.skeleton;
  std::ostringstream out;
  out << "Rig device for " << (plan.character.empty() ? std::string("the character") : "'" + printable(plan.character, 80) + "'")
      << ": " << plan.joint_count() << " joint(s), " << plan.splitter_count() << " splitter(s).\n"
      << "Build it in this order; the numbers match the picture. Angles are in degrees; a joint's inlet twist "
         "ring stays at 0.\n";
  if (plan.modules.empty()) out << "The plan has no module: nothing to build.\n";
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    out << "\n" << (i + 1) << ". ";
    if (m.type == DeviceModule::Type::joint) {
      const rig_device::JointAngles a = rig_device::joint_angles_for(m.q_in_out_rest, 0.0);
      out << "Joint (module " << (i + 1) << "): plug its inlet into " << where(plan, m) << ".\n"
          << "   It drives rig node " << node_name(sk, m.rig_node) << ".\n"
          << "   Rest setting: inlet twist " << deg(a.twist_in_rad) << ", bend x " << deg(a.bend_x_rad)
          << ", bend y " << deg(a.bend_y_rad) << ", outlet twist " << deg(a.twist_out_rad) << ".\n";
    } else {
      out << "Splitter " << printable(m.kind, 40) << " (module " << (i + 1) << "): plug its inlet into "
          << where(plan, m) << ", turned " << deg(turn_about_inlet_rad(m.q_in_out_rest))
          << " about the inlet shaft.\n"
          << "   It sits at rig node " << node_name(sk, m.rig_node) << ".";
      for (std::size_t o = 0; o < m.outlet_rig_child.size(); ++o) {
        const int c = m.outlet_rig_child[o];
        out << (o == 0 ? " " : "; ") << "outlet " << o << ": "
            << (c >= 0 ? "towards " + node_name(sk, c) : std::string("unused"));
      }
      out << ".\n";
      if (m.angular_error_rad > 0.0)
        out << "   Its outlets differ from the rig's branches by " << deg(m.angular_error_rad) << " on average.\n";
    }
  }
  return out.str();
}

Result<std::string> assembly_svg(const RigInput& input, const Plan& plan, const AssemblyOptions& options) {
  using assembly_detail::check;
  using assembly_detail::xml;
  if (Status s = options.validate(); !s) return s.error();
  if (Status s = check(input, plan); !s) return s.error();
  const Skeleton& sk = input.skeleton;
  std::vector<Pose> T_world_node;
  forward_kinematics(sk, rest_pose(sk), T_world_node);

  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 hi = -lo;
  for (const Pose& T : T_world_node) {
    lo = lo.cwiseMin(T.p);
    hi = hi.cwiseMax(T.p);
  }
  const Vec3 extent = (hi - lo).cwiseMax(1e-6);
  const double margin = 40.0;
  const double W = options.view_width_px, H = options.view_height_px;
  const double scale = std::min((W - 2 * margin) / std::max(extent.x(), extent.z()), (H - 2 * margin) / extent.y());
  const Vec3 centre = 0.5 * (lo + hi);
  // View v: 0 front (x, y), 1 side (z, y). SVG's y grows downwards.
  const auto to_px = [&](int view, const Vec3& p) {
    const double u = view == 0 ? p.x() - centre.x() : p.z() - centre.z();
    return Eigen::Vector2d(view * W + 0.5 * W + scale * u, 0.5 * H - scale * (p.y() - centre.y()) + 30.0);
  };
  const double legend_line = 18.0;
  const double legend_top = H + 50.0;
  const double total_h = legend_top + legend_line * static_cast<double>(plan.modules.size() + 3) + 20.0;

  std::ostringstream svg;
  svg << std::fixed << std::setprecision(1);
  svg << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << 2 * W << "\" height=\"" << total_h
      << "\" viewBox=\"0 0 " << 2 * W << " " << total_h << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
      << "<title>Rig device for " << xml(plan.character) << "</title>\n"
      << "<rect x=\"0\" y=\"0\" width=\"" << 2 * W << "\" height=\"" << total_h << "\" fill=\"white\"/>\n"
      << "<text x=\"10\" y=\"20\" font-size=\"14\">Front (x right, y up)</text>\n"
      << "<text x=\"" << W + 10 << "\" y=\"20\" font-size=\"14\">Side (z right, y up)</text>\n"
      << "<line x1=\"" << W << "\" y1=\"0\" x2=\"" << W << "\" y2=\"" << H + 30 << "\" stroke=\"#ccc\"/>\n";
  svg << "<g id=\"skeleton\" stroke=\"#888\" stroke-width=\"2\">\n";
  for (int view = 0; view < 2; ++view)
    for (std::size_t b = 0; b < sk.size(); ++b) {
      const int p = sk.parent[b];
      if (p < 0) continue;
      const auto a = to_px(view, T_world_node[static_cast<std::size_t>(p)].p);
      const auto c = to_px(view, T_world_node[b].p);
      svg << "<line x1=\"" << a.x() << "\" y1=\"" << a.y() << "\" x2=\"" << c.x() << "\" y2=\"" << c.y() << "\"/>\n";
    }
  svg << "</g>\n<g id=\"nodes\" fill=\"#888\">\n";
  for (int view = 0; view < 2; ++view)
    for (std::size_t b = 0; b < sk.size(); ++b) {
      const auto c = to_px(view, T_world_node[b].p);
      svg << "<circle cx=\"" << c.x() << "\" cy=\"" << c.y() << "\" r=\"2.5\"/>\n";
      if (options.label_all_nodes && view == 0)
        svg << "<text x=\"" << c.x() + 4 << "\" y=\"" << c.y() - 4 << "\" font-size=\"9\">" << xml(sk.names[b])
            << "</text>\n";
    }
  svg << "</g>\n";
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    const bool joint = m.type == DeviceModule::Type::joint;
    svg << "<g id=\"module-" << i + 1 << "\" class=\"" << (joint ? "joint" : "splitter") << "\">\n";
    for (int view = 0; view < 2; ++view) {
      auto c = to_px(view, T_world_node[static_cast<std::size_t>(m.rig_node)].p);
      if (joint) {
        svg << "<circle cx=\"" << c.x() << "\" cy=\"" << c.y() << "\" r=\"8\" fill=\"#d62728\"/>\n";
      } else {
        c += Eigen::Vector2d(6.0, 6.0);  // off the joint that may drive the same node
        svg << "<rect x=\"" << c.x() - 7 << "\" y=\"" << c.y() - 7
            << "\" width=\"14\" height=\"14\" fill=\"#1f77b4\"/>\n";
      }
      svg << "<text x=\"" << c.x() << "\" y=\"" << c.y() + 4 << "\" fill=\"white\" font-size=\"10\" "
          << "text-anchor=\"middle\">" << i + 1 << "</text>\n";
    }
    svg << "</g>\n";
  }
  svg << "<g id=\"legend\">\n"
      << "<circle cx=\"18\" cy=\"" << legend_top - 4 << "\" r=\"6\" fill=\"#d62728\"/>"
      << "<text x=\"30\" y=\"" << legend_top << "\">joint, on the rig node it drives</text>\n"
      << "<rect x=\"250\" y=\"" << legend_top - 10 << "\" width=\"12\" height=\"12\" fill=\"#1f77b4\"/>"
      << "<text x=\"268\" y=\"" << legend_top << "\">splitter, on the branching node it sits at</text>\n";
  for (std::size_t i = 0; i < plan.modules.size(); ++i) {
    const DeviceModule& m = plan.modules[i];
    svg << "<text x=\"12\" y=\"" << legend_top + legend_line * static_cast<double>(i + 1) << "\">" << i + 1 << ": "
        << (m.type == DeviceModule::Type::joint ? std::string("joint driving ") : "splitter " + xml(m.kind) + " at ")
        << xml(sk.names[static_cast<std::size_t>(m.rig_node)]) << ", on "
        << xml(assembly_detail::where(plan, m)) << "</text>\n";
  }
  svg << "</g>\n</svg>\n";
  return svg.str();
}

}  // namespace proprio::rig_plan
