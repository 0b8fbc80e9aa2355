// Timing of the reconstruction pipeline, run by hand (timing has no place in
// unit tests):
//   stretch_array_recon_bench [THESIS_ONNX]
// THESIS_ONNX: tests/data/stretch_array_recon/make_models.py thesis OUT_DIR
// writes it (40 MB, never committed); without it the DNN part is skipped.
// Prints the prototype_92 mesh, the per-frame ARAP time with its markers as
// constraints, the labelling of 3000 synthetic frames with a few hundred
// labels, and the per-frame DNN and ARAP times of the ArrayReconstructor.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <random>

#include "proprio/stretch_array_recon/array_reconstructor.hpp"
#include "proprio/stretch_array_recon/marker_labelling.hpp"

using namespace proprio;
using namespace proprio::stretch_array_recon;
using clk = std::chrono::steady_clock;

namespace {

double secs(clk::time_point a, clk::time_point b) { return std::chrono::duration<double>(b - a).count(); }

// A sheet bending back and forth between flat-ish and a 7 cm cylinder while
// it turns: the rest shape at radius r(t), moved rigidly.
Eigen::MatrixX3d pose(const ReconMesh& mesh, std::size_t t) {
  const double u = 0.5 - 0.5 * std::cos(static_cast<double>(t) * 0.01);
  Eigen::MatrixX3d V = rest_shape(mesh, 1.0 / (0.5 + 13.5 * u));
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() =
      Eigen::AngleAxisd(0.3 * std::sin(static_cast<double>(t) * 0.003), Eigen::Vector3d(0.3, 1, 0.2).normalized())
          .toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.4, 1.1, 0.2);
  return (V * T.linear().transpose()).rowwise() + T.translation().transpose();
}

}  // namespace

int main(int argc, char** argv) {
  const auto layout = stretch_array::StripArrayLayout::prototype_92();
  auto t0 = clk::now();
  auto mesh = build_recon_mesh(layout);
  auto t1 = clk::now();
  if (!mesh) return std::fprintf(stderr, "%s\n", mesh.error().message.c_str()), 1;
  auto markers = select_marker_vertices(*mesh);
  if (!markers) return std::fprintf(stderr, "%s\n", markers.error().message.c_str()), 1;
  const std::size_t M = markers->size();
  std::printf("prototype_92 mesh: %zu vertices, %zu triangles, outline edge %.1f mm, %zu markers; built in %.1f ms\n",
              mesh->vertex_count(), mesh->triangles.size(), mesh->outline_edge_m * 1e3, M, secs(t0, t1) * 1e3);

  // ARAP per frame, warm-started, as the reconstructor runs it.
  {
    ArapOptions o;
    o.max_iterations = 4;
    o.tolerance_m = 2e-5;
    auto arap = ArapDeformer::create(rest_shape(*mesh), mesh->triangles, o);
    Eigen::MatrixX3d V, targets(static_cast<Eigen::Index>(M), 3);
    const int frames = 1000;
    std::vector<double> times;
    double err = 0.0;
    int iters = 0;
    for (int t = 0; t < frames; ++t) {
      const Eigen::MatrixX3d truth = pose(*mesh, static_cast<std::size_t>(t));
      for (std::size_t k = 0; k < M; ++k) targets.row(static_cast<Eigen::Index>(k)) = truth.row((*markers)[k]);
      ArapStats st;
      const auto a = clk::now();
      if (!arap->solve(*markers, targets, V, &st)) return 1;
      times.push_back(secs(a, clk::now()));
      iters += st.iterations;
      err += (V - truth).rowwise().norm().mean();
    }
    std::sort(times.begin(), times.end());
    std::printf(
        "ARAP (%d frames, %zu constraints, <= %d iterations): median %.3f ms, p95 %.3f ms, mean %.2f iterations, "
        "mean vertex error %.2f mm vs the bent truth\n",
        frames, M, o.max_iterations, times[times.size() / 2] * 1e3, times[times.size() * 95 / 100] * 1e3,
        static_cast<double>(iters) / frames, err / frames * 1e3);
  }

  // Labelling: 3000 frames, markers lost for 20-200 frames and found again
  // under new labels, a ghost now and then.
  {
    std::mt19937 rng(30);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    std::normal_distribution<double> noise(0.0, 0.0003);
    const std::size_t F = 3000;
    std::vector<MocapFrame> frames(F);
    std::vector<std::uint32_t> label(M);
    std::vector<std::size_t> hidden_until(M, 0);
    std::uint32_t next = 1000;
    std::map<std::uint32_t, int> truth_of;  // label -> marker, -1 ghost
    std::vector<std::vector<MocapObservation>> ghost(F);
    for (std::size_t k = 0; k < M; ++k) label[k] = static_cast<std::uint32_t>(k);
    for (std::size_t t = 0; t < F; ++t) {
      const Eigen::MatrixX3d truth = pose(*mesh, t);
      frames[t].t_s = static_cast<double>(t) / 120.0;
      for (std::size_t k = 0; k < M; ++k) {
        if (t > 0 && hidden_until[k] <= t && uni(rng) < 0.003) {
          hidden_until[k] = t + 5 + static_cast<std::size_t>(uni(rng) * 40);
          label[k] = next++;
        }
        truth_of[label[k]] = static_cast<int>(k);
        if (hidden_until[k] > t) continue;
        frames[t].observations.push_back(
            {label[k], truth.row((*markers)[k]).transpose() + Eigen::Vector3d(noise(rng), noise(rng), noise(rng))});
      }
      // Ghosts: 4-10 cm off a marker, for a few frames.
      if (uni(rng) < 0.03) {
        const std::uint32_t g = next++;
        truth_of[g] = -1;
        const std::size_t k = static_cast<std::size_t>(uni(rng) * static_cast<double>(M)) % M;
        const Eigen::Vector3d off =
            Eigen::Vector3d(uni(rng) - 0.5, uni(rng) - 0.5, uni(rng) - 0.5).normalized() * (0.04 + 0.06 * uni(rng));
        for (std::size_t d = 0; d < 8 && t + d < F; ++d)
          ghost[t + d].push_back({g, truth.row((*markers)[k]).transpose() + off});
      }
      for (const auto& o : ghost[t]) frames[t].observations.push_back(o);
    }
    LabellingOptions o;
    const auto a = clk::now();
    auto r = label_markers(rest_shape(*mesh), mesh->triangles, *markers, frames,
                           {{0, 0}, {1, 1}, {static_cast<std::uint32_t>(M - 1), M - 1}}, o);
    const double s = secs(a, clk::now());
    if (!r) return std::fprintf(stderr, "%s\n", r.error().message.c_str()), 1;
    std::size_t right = 0, wrong = 0;
    std::size_t ghosts_taken = 0, real_rejected = 0, swapped = 0;
    for (const auto& [l, m] : r->marker_of_label) {
      const int want = truth_of.at(l);
      (want == m ? right : wrong) += 1;
      if (want != m) (want < 0 ? ghosts_taken : m < 0 ? real_rejected : swapped) += 1;
    }
    std::printf("wrong labels: %zu ghosts taken as markers, %zu real tracks rejected, %zu given the wrong marker\n",
                ghosts_taken, real_rejected, swapped);
    std::printf("labelling (%zu frames x %zu markers; %s): %s; %zu labels right, %zu wrong; %.1f s\n", F, M,
                o.describe().c_str(), r->describe().c_str(), right, wrong, s);
  }

  if (argc > 1) {
    MarkerRegressorOptions ro;
    auto reg = MarkerRegressor::load(argv[1], layout.cell_count(), M, ro);
    if (!reg) return std::fprintf(stderr, "%s\n", reg.error().message.c_str()), 1;
    auto rec = ArrayReconstructor::create(*mesh, *markers, std::move(*reg));
    if (!rec) return std::fprintf(stderr, "%s\n", rec.error().message.c_str()), 1;
    std::mt19937 rng(1);
    std::normal_distribution<double> n(1.0, 0.05);
    Eigen::VectorXd cells(static_cast<Eigen::Index>(layout.cell_count()));
    ReconstructedFrame out;
    std::vector<double> dnn, arap, total;
    // The random network's markers are not a plausible sheet; feed its
    // output's ARAP the same way regardless (the cost is what is measured).
    for (int t = 0; t < 500; ++t) {
      for (Eigen::Index i = 0; i < cells.size(); ++i) cells(i) = n(rng);
      const auto a = clk::now();
      if (!rec->reconstruct(cells, out)) return 1;
      total.push_back(secs(a, clk::now()));
      dnn.push_back(out.regressor_s);
      arap.push_back(out.arap_s);
    }
    for (auto* v : {&dnn, &arap, &total}) std::sort(v->begin(), v->end());
    std::printf(
        "reconstructor (%s, 500 frames, 1 OpenCV thread): median DNN %.3f ms, ARAP %.3f ms, total %.3f ms (p95 %.3f "
        "ms)\n",
        argv[1], dnn[250] * 1e3, arap[250] * 1e3, total[250] * 1e3, total[475] * 1e3);
  }
  return 0;
}
