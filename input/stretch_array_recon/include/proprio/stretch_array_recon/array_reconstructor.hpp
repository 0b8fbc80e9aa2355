#pragma once
// From cell readings to the deformed sheet (Glauser 2019, Sec. 4.4.3): cell
// ratios C/C0 -> regressor -> marker positions -> the rest mesh S^0 deformed
// (ARAP, see arap.hpp for why not Wang et al. 2015) with the markers as
// positional constraints -> every vertex's position.
//
// Once per session the rest mesh is moved by Procrustes onto the markers of a
// rest frame (align_session); until then the first frame aligns it. ARAP's
// result does not depend on that rigid placement, but its first guess does:
// after that each frame starts from the last one (warm start), so a frame
// costs a few local-global iterations with one cached factorisation (the
// marker set never changes).
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "proprio/core/result.hpp"
#include "proprio/stretch_array_recon/arap.hpp"
#include "proprio/stretch_array_recon/marker_regressor.hpp"
#include "proprio/stretch_array_recon/recon_mesh.hpp"

namespace proprio::stretch_array_recon {

struct ArrayReconstructorOptions {
  double rest_cylinder_radius_m = 0.0;  // S^0: flat (0) or wrapped, see rest_shape()
  ArapOptions arap{/*max_iterations=*/4, /*tolerance_m=*/2e-5, /*factor_cache_size=*/2};
  Status validate() const;
  std::string describe() const;
};

struct ReconstructedFrame {
  Eigen::MatrixX3d markers_m;              // M x 3, the regressor's output
  Eigen::MatrixX3d vertices_m;             // n x 3, the deformed S^0
  double regressor_s = 0.0, arap_s = 0.0;  // wall time of each stage
  int arap_iterations = 0;
};

class ArrayReconstructor {
 public:
  // marker_vertices: the mesh vertices the regressor's markers are, in its
  // output order (regressor.marker_count() of them).
  static Result<ArrayReconstructor> create(ReconMesh mesh, std::vector<std::uint32_t> marker_vertices,
                                           MarkerRegressor regressor, const ArrayReconstructorOptions& options = {});

  // Procrustes of S^0's marker vertices onto a rest frame's markers (or the
  // regressor's output for rest cells); resets the warm start.
  Status align_session(const Eigen::MatrixX3d& rest_markers_m);
  Status align_session_from_cells(const Eigen::VectorXd& rest_cells);

  // One frame. On error `out` keeps the last good vertices.
  Status reconstruct(const Eigen::VectorXd& cells, ReconstructedFrame& out);
  // The deformation alone, for markers from elsewhere (e.g. labelled mocap).
  Status deform(const Eigen::MatrixX3d& markers_m, Eigen::MatrixX3d& vertices_m, ArapStats* stats = nullptr);

  const ReconMesh& mesh() const noexcept { return mesh_; }
  const std::vector<std::uint32_t>& marker_vertices() const noexcept { return markers_; }
  const Eigen::Isometry3d& T_session_rest() const noexcept { return T_session_rest_; }
  bool aligned() const noexcept { return aligned_; }
  MarkerRegressor& regressor() noexcept { return regressor_; }

 private:
  ArrayReconstructor(ReconMesh mesh, std::vector<std::uint32_t> markers, MarkerRegressor regressor, ArapDeformer arap)
      : mesh_(std::move(mesh)),
        markers_(std::move(markers)),
        regressor_(std::move(regressor)),
        arap_(std::move(arap)) {}
  ReconMesh mesh_;
  std::vector<std::uint32_t> markers_;
  MarkerRegressor regressor_;
  ArapDeformer arap_;
  Eigen::Isometry3d T_session_rest_ = Eigen::Isometry3d::Identity();
  bool aligned_ = false;
  Eigen::MatrixX3d last_;  // warm start
};

}  // namespace proprio::stretch_array_recon
