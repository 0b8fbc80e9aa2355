#pragma once
// The elastic sheet on a moving body (issue 30): the ground truth of the
// stretch-array simulator. The flat rest mesh (stretch_array::SheetMesh) is
// wrapped onto the body proxy -- sheet x around the axis (arc length), sheet
// y along it -- and then follows the body quasi-statically: every step
// minimises the membrane energy (membrane.hpp) plus the friction springs over
// the vertices' surface coordinates, so the sheet never leaves the surface (a
// tight sleeve).
//
// Friction and slip. Each vertex is tied to a skin material point (its
// anchor) by a tangential spring of stiffness k_i = friction_stiffness * A_i
// (A_i its rest area). After each solve the spring force is compared with a
// Coulomb limit (friction_coefficient * N_i + adhesion_pa * A_i), where N_i is
// the normal force the stretched membrane presses the vertex onto the body
// with -- the normal component of its elastic force, i.e. tension times
// curvature (Laplace) integrated over the vertex's area. Where the spring
// exceeds the limit the anchor slides along the skin until the spring sits at
// the limit (return mapping), and the step is re-solved with the new anchors.
//
// Placement (donning). The sheet's centre goes to the body's default site
// moved by the placement's offsets; the sheet is turned in its plane and
// pre-stretched (so it is tight), and each vertex is stuck to the skin point
// under it; where the pre-stretch pulls harder than friction holds (the free
// edges) the sheet then creeps at t = 0 until it holds. A re-donned sleeve is another placement a few mm and degrees off
// (SheetPlacement::redonned).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/result.hpp"
#include "proprio/elastic_sheet/body_proxy.hpp"
#include "proprio/elastic_sheet/membrane.hpp"
#include "proprio/stretch_array/array_layout.hpp"

namespace proprio::elastic_sheet {

namespace detail {
class MembraneSolver;
}

struct SheetPlacement {
  double axial_offset_m = 0.0;         // along the body axis from the default site
  double around_angle_rad = 0.0;       // around the axis from the default site
  double inplane_rotation_rad = 0.0;   // the sheet turned on the skin
  double prestretch_around = 1.05;     // pulled tight around the limb
  double prestretch_along = 1.0;
  Status validate() const;
  std::string describe() const;
  // This placement moved by uniform offsets within the given bounds (seeded):
  // taking the sleeve off and putting it on again.
  SheetPlacement redonned(std::uint64_t seed, double max_offset_m = 0.004, double max_angle_rad = 0.07,
                          double max_rotation_rad = 0.05) const;
};

struct FrictionOptions {
  double stiffness_pa_per_m = 5.0e7;  // tangential spring per rest area (N/m^3)
  double friction_coefficient = 0.5;  // silicone on skin or a nylon sock (B.3)
  double adhesion_pa = 5000.0;        // stick limit without pressure (silicone is tacky)
  bool slip = true;                   // false: the sheet never slides on the skin
  Status validate() const;
};

struct SheetSolverOptions {
  int max_iterations = 20;         // per solve, warm-started
  double tolerance_m = 5.0e-6;     // stop when the next quasi-Newton step moves no vertex further
  double max_step_m = 0.005;       // keeps the per-step linearisation of the surface valid
  int slip_passes = 1;             // re-solves after anchors slid, per step
  Status validate() const;
};

struct ElasticSheetOptions {
  MembraneMaterial material;  // from_layout() fills it from layout.sheet
  SheetPlacement placement;
  FrictionOptions friction;
  SheetSolverOptions solver;
  Status validate() const;
  std::string describe() const;
  static ElasticSheetOptions from_layout(const stretch_array::StripArrayLayout& layout);
};

struct SheetStepStats {
  int iterations = 0;          // all solves of the step together
  bool converged = false;
  double energy_j = 0.0;
  std::size_t slipping_vertices = 0;  // anchors that slid more than 0.1 um (most in one pass)
  double max_slip_m = 0.0;            // largest anchor slide this step
};

class ElasticSheet {
 public:
  // Wraps the rest mesh onto the body at t = 0 and solves its equilibrium.
  static Result<ElasticSheet> create(SheetMesh mesh, std::shared_ptr<const BodyProxy> body,
                                     const ElasticSheetOptions& options);
  ElasticSheet(ElasticSheet&&) noexcept;
  ElasticSheet& operator=(ElasticSheet&&) noexcept;
  ~ElasticSheet();

  // Quasi-static equilibrium at time t (seconds; any order, but small steps
  // between calls are what the warm start and the slip history assume).
  Result<SheetStepStats> step(double t_s);

  double time_s() const noexcept { return t_s_; }
  const SheetMesh& mesh() const noexcept { return mesh_; }
  const BodyProxy& body() const noexcept { return *body_; }
  // Body frame, same order as mesh().vertices_m.
  const std::vector<Vec3>& vertices_m() const noexcept { return x_; }
  // Each vertex's surface coordinates and the skin point it is stuck to.
  const std::vector<Vec2>& surface_uv_m() const noexcept { return q_; }
  const std::vector<Vec2>& anchor_uv_m() const noexcept { return anchor_; }
  // The vertices' rest positions on the skin (where they were donned).
  const std::vector<Vec2>& donned_uv_m() const noexcept { return donned_; }
  std::vector<std::pair<std::string, double>> pose_values() const { return body_->pose_values(t_s_); }
  const SheetStepStats& last_stats() const noexcept { return stats_; }
  const ElasticSheetOptions& options() const noexcept { return options_; }

 private:
  ElasticSheet() = default;
  Result<SheetStepStats> solve_at(double t_s, int max_iterations);

  SheetMesh mesh_;
  std::shared_ptr<const BodyProxy> body_;
  ElasticSheetOptions options_;
  std::unique_ptr<Membrane> membrane_;
  std::unique_ptr<detail::MembraneSolver> solver_;
  std::vector<Vec3> x_;
  std::vector<Vec2> q_, anchor_, donned_;
  std::vector<double> spring_k_;
  double t_s_ = 0.0;
  SheetStepStats stats_;
};

}  // namespace proprio::elastic_sheet
