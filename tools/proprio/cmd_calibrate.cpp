// proprio calibrate stereo: calibrate VIST's stereo camera from checkerboard
// image pairs; write the full calibration (distortion, rectification) and the
// rectified rig as a glove file's [rig] table.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "commands.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/glove_descriptions/imu_glove_description.hpp"
#include "proprio/core/log.hpp"
#include "proprio/vist/stereo_calibration.hpp"

namespace proprio::cli {

namespace {

struct CalibrateStereoArgs {
  std::string images;
  bool side_by_side = false;
  std::string board;
  double square_mm = 0.0;
  double alpha = 0.0;
  bool k3 = false;
  int min_pairs = 6;
  std::string out = "stereo_calibration.yaml";
  std::string rig_toml;
  std::string glove;
  double rate_hz = 0.0;
  bool force = false;
};

bool refuse_overwrite(const std::string& path, bool force) {
  std::error_code ec;
  if (!force && std::filesystem::exists(path, ec)) {
    logger().error("'{}' exists; pass --force to overwrite it (a calibration is worth keeping)", path);
    return true;
  }
  return false;
}

int run_calibrate_stereo(const CalibrateStereoArgs& a) {
  auto board = vist::CheckerboardSpec::parse(a.board, a.square_mm);
  if (!board) return logger().error("--board/--square-mm: {}", board.error().message), 1;
  vist::StereoCalibrationOptions options;
  options.board = *board;
  options.alpha = a.alpha;
  options.fix_k3 = !a.k3;
  options.min_pairs = a.min_pairs;
  if (auto s = options.validate(); !s) return logger().error("{}", s.error().message), 1;

  // The mount and the rate are not something a checkerboard can tell; they
  // come from the user's glove file or stay the ZED Mini-like defaults.
  StereoRig mount = StereoRig::zed_mini_like();
  if (!a.glove.empty()) {
    auto g = ImuGloveDescription::load(a.glove);
    if (!g) return logger().error("--glove: {}", g.error().message), 1;
    mount = g->rig;
  }
  const double rate_hz = a.rate_hz > 0.0 ? a.rate_hz : mount.rate_hz;
  if (refuse_overwrite(a.out, a.force)) return 1;
  if (!a.rig_toml.empty() && refuse_overwrite(a.rig_toml, a.force)) return 1;

  std::printf("calibrating from %s images in %s; %s\n", a.side_by_side ? "side-by-side" : "left/right",
              a.images.c_str(), options.describe().c_str());
  auto progress = [&](std::size_t i, std::size_t n, const vist::BoardDetection& d) {
    const char* what = d.usable()        ? "board found in both images"
                       : d.found_left    ? "board NOT found in the right image: skipped"
                       : d.found_right   ? "board NOT found in the left image: skipped"
                       : d.image_size.empty() ? "left and right images differ in size"
                                              : "board not found: skipped";
    std::printf("[%3zu/%zu] %s: %s\n", i + 1, n, d.name.c_str(), what);
    std::fflush(stdout);
  };
  auto cal = vist::calibrate_stereo_folder(a.images, a.side_by_side, options, progress);
  if (!cal) return logger().error("{}", cal.error().message), 1;

  std::printf("\n%s\n", cal->describe().c_str());
  if (auto s = cal->save(a.out); !s) return logger().error("{}", s.error().message), 1;

  const StereoRig rig = cal->rectified_rig(rate_hz, mount.T_head_leftcam);
  char rms[32];
  std::snprintf(rms, sizeof rms, "%.3f", cal->rms_stereo_px);
  std::string toml =
      "# Rectified stereo rig from 'proprio calibrate stereo' (" + std::to_string(cal->pairs.size()) +
      " pairs, stereo RMS " + rms + " px); full calibration in " + a.out + ".\n" +
      (a.glove.empty()
           ? "# rate_hz and the left camera's mount are ZED Mini-like defaults, not calibrated: edit them (or pass "
             "--glove).\n"
           : "# rate_hz and the left camera's mount are from " + a.glove + ".\n") +
      vist::rig_toml_snippet(rig);
  std::printf("\nglove file [rig] table (replace the [rig] table of your glove file with it):\n\n%s\n", toml.c_str());
  if (!a.rig_toml.empty()) {
    if (auto s = write_file_atomic(a.rig_toml, toml, "rig table"); !s) return report_error(s.error());
    std::printf("wrote %s\n", a.rig_toml.c_str());
  }
  std::printf("wrote %s (intrinsics, distortion, extrinsics, rectification; StereoCalibration::load)\n",
              a.out.c_str());
  if (!cal->outlier_names().empty()) {
    logger().warn("{} pair(s) have reprojection errors far above the rest (listed above); check them, remove the "
                  "bad ones and calibrate again",
                  cal->outlier_names().size());
  }
  if (cal->pairs.size() < 10) {
    logger().warn("only {} usable pairs; 15-25 at varied distances and tilts give a steadier calibration",
                  cal->pairs.size());
  }
  return 0;
}

}  // namespace

void add_calibrate_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<CalibrateStereoArgs>();
  // The description is the command table's (command_table.cpp): `calibrate` spans programs.
  CLI::App* cmd = add_command(app, "calibrate stereo");
  cmd->add_option("--images", args->images, "Folder with the calibration images")->required();
  cmd->add_flag("--side-by-side", args->side_by_side, "Each image holds both cameras, left half = left camera");
  cmd->add_option("--board", args->board,
                  "Inner corners COLSxROWS (where four squares meet: a board of 10x7 squares is 9x6)")
      ->required();
  cmd->add_option("--square-mm", args->square_mm, "Edge of one printed square as measured, millimetres")
      ->required()
      ->check(CLI::Range(0.1, 1000.0));
  cmd->add_option("--alpha", args->alpha,
                  "Rectification scaling: 0 keeps only pixels valid in both images (no black borders), 1 keeps "
                  "every source pixel")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_flag("--k3", args->k3, "Also fit the third radial distortion term (wide-angle lenses, many boards)");
  cmd->add_option("--min-pairs", args->min_pairs, "Fewest usable pairs accepted")
      ->check(CLI::Range(3, 1000))
      ->capture_default_str();
  cmd->add_option("--out", args->out, "Full calibration to write (OpenCV YAML, or JSON by extension)")
      ->capture_default_str();
  cmd->add_option("--rig-toml", args->rig_toml, "Also write the [rig] table to this file");
  cmd->add_option("--glove", args->glove,
                  "Glove file whose [rig] gives the camera mount in the head and the frame rate (these are not "
                  "calibrated here); default: ZED Mini-like")
      ->check(CLI::ExistingFile);
  cmd->add_option("--rate-hz", args->rate_hz, "Frame rate for the [rig] table, Hz (default: from --glove, or 30)")
      ->check(CLI::Range(0.0, 10000.0));
  cmd->add_flag("--force", args->force, "Overwrite existing output files");
  cmd->callback([args, &exit_code] { exit_code = run_calibrate_stereo(*args); });
}

}  // namespace proprio::cli
