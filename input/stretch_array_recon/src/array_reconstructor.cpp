#include "proprio/stretch_array_recon/array_reconstructor.hpp"

#include <chrono>
#include <cmath>
#include <set>

namespace proprio::stretch_array_recon {

Status ArrayReconstructorOptions::validate() const {
  if (!(rest_cylinder_radius_m >= 0) || !std::isfinite(rest_cylinder_radius_m)) {
    return make_error(Errc::invalid_argument, "rest_cylinder_radius_m must be >= 0 metres (0: flat)");
  }
  return arap.validate();
}

std::string ArrayReconstructorOptions::describe() const {
  return "rest_cylinder_radius_m=" + std::to_string(rest_cylinder_radius_m) + " arap: " + arap.describe();
}

Result<ArrayReconstructor> ArrayReconstructor::create(ReconMesh mesh, std::vector<std::uint32_t> marker_vertices,
                                                      MarkerRegressor regressor,
                                                      const ArrayReconstructorOptions& options) {
  if (Status s = options.validate(); !s) return s.error();
  if (marker_vertices.size() != regressor.marker_count()) {
    return make_error(Errc::invalid_argument, "the regressor gives " + std::to_string(regressor.marker_count()) +
                                                  " markers but " + std::to_string(marker_vertices.size()) +
                                                  " marker vertices were given; use the marker set it was trained on");
  }
  if (regressor.cell_count() != mesh.centroid_vertex.size()) {
    return make_error(Errc::invalid_argument, "the regressor reads " + std::to_string(regressor.cell_count()) +
                                                  " cells, the mesh has " +
                                                  std::to_string(mesh.centroid_vertex.size()));
  }
  if (marker_vertices.size() < 3)
    return make_error(Errc::invalid_argument, "at least 3 markers are needed to place the sheet");
  std::set<std::uint32_t> unique(marker_vertices.begin(), marker_vertices.end());
  if (unique.size() != marker_vertices.size() || *unique.rbegin() >= mesh.vertex_count()) {
    return make_error(Errc::invalid_argument, "marker vertices must be distinct vertices of the mesh");
  }
  auto arap = ArapDeformer::create(rest_shape(mesh, options.rest_cylinder_radius_m), mesh.triangles, options.arap);
  if (!arap) return arap.error();
  return ArrayReconstructor(std::move(mesh), std::move(marker_vertices), std::move(regressor), std::move(*arap));
}

Status ArrayReconstructor::align_session(const Eigen::MatrixX3d& rest_markers_m) {
  if (rest_markers_m.rows() != static_cast<Eigen::Index>(markers_.size())) {
    return make_error(Errc::invalid_argument, "align_session: " + std::to_string(rest_markers_m.rows()) +
                                                  " markers, expected " + std::to_string(markers_.size()));
  }
  Eigen::MatrixX3d from(rest_markers_m.rows(), 3);
  for (std::size_t k = 0; k < markers_.size(); ++k)
    from.row(static_cast<Eigen::Index>(k)) = arap_.rest().row(markers_[k]);
  auto T = fit_rigid(from, rest_markers_m);
  if (!T) return T.error().with_context("align_session");
  T_session_rest_ = *T;
  aligned_ = true;
  last_ = (arap_.rest() * T->linear().transpose()).rowwise() + T->translation().transpose();
  return {};
}

Status ArrayReconstructor::align_session_from_cells(const Eigen::VectorXd& rest_cells) {
  Eigen::MatrixX3d m;
  if (Status s = regressor_.predict(rest_cells, m); !s) return s;
  return align_session(m);
}

Status ArrayReconstructor::deform(const Eigen::MatrixX3d& markers_m, Eigen::MatrixX3d& vertices_m, ArapStats* stats) {
  if (!aligned_) {
    if (Status s = align_session(markers_m); !s) return s;
  }
  vertices_m = last_;
  if (Status s = arap_.solve(markers_, markers_m, vertices_m, stats); !s) return s;
  last_ = vertices_m;
  return {};
}

Status ArrayReconstructor::reconstruct(const Eigen::VectorXd& cells, ReconstructedFrame& out) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  Eigen::MatrixX3d markers;
  if (Status s = regressor_.predict(cells, markers); !s) return s;
  const auto t1 = clock::now();
  Eigen::MatrixX3d V;
  ArapStats st;
  if (Status s = deform(markers, V, &st); !s) return s;
  const auto t2 = clock::now();
  out.markers_m = std::move(markers);
  out.vertices_m = std::move(V);
  out.regressor_s = std::chrono::duration<double>(t1 - t0).count();
  out.arap_s = std::chrono::duration<double>(t2 - t1).count();
  out.arap_iterations = st.iterations;
  return {};
}

}  // namespace proprio::stretch_array_recon
