#include "proprio/sim/stereo_image_sim.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <span>

#include <opencv2/imgproc.hpp>

namespace proprio::sim {

namespace {

constexpr std::uint8_t kNoBody = 255;
constexpr std::uint8_t kFirstMarkerId = 64;  // owner ids from here on are markers (64 + index); below: hand bodies

// Random streams (mix_seed(seed, stream)); each effect has its own, so
// switching one off leaves the others as they were.
enum : std::uint64_t {
  kWallStream = 0x51a0,
  kDistractorStream,
  kMarkerLookStream,
  kExposureStream,
  kNoiseStream,  // + camera index
  // Camera realism (clear of kNoiseStream + camera index).
  kLensStream = 0x51b0,
  kColourCastStream,
  kGradientStream,
  kGlossStream,
};

// The exposure and light level at which sensor_gain_dn_per_e and
// pixel_noise_dn are given (StereoImageSimOptions::gain_ratio()).
constexpr double kReferenceExposureS = 0.004;
// Motion blur: sub-exposure positions of a marker at most this far apart in
// the image (pixels; each is 4x4 anti-aliased at its edge), and at most this many.
constexpr double kBlurStepPx = 0.5;
constexpr int kMaxBlurSteps = 64;

// The rigid body a segment moves with: the non-thumb metacarpals are rigid
// with the wrist in the hand model (as in stereo_sim.cpp, where it is private).
HandJoint body_of(HandJoint segment) noexcept {
  switch (segment) {
    case HandJoint::palm:
    case HandJoint::index_metacarpal:
    case HandJoint::middle_metacarpal:
    case HandJoint::ring_metacarpal:
    case HandJoint::little_metacarpal: return HandJoint::wrist;
    default: return segment;
  }
}

bool finite_in(double x, double lo, double hi) { return std::isfinite(x) && x >= lo && x <= hi; }

// HSV with the hue on OpenCV's HSV_FULL scale (256 steps over 360 deg),
// s in [0, 1], v in [0, 255] -> BGR.
cv::Vec3d hsv_full_to_bgr(double hue_code, double s, double v) {
  double h = std::fmod(hue_code * (6.0 / 256.0), 6.0);
  if (h < 0.0) h += 6.0;
  const int sector = std::min(5, static_cast<int>(h));
  const double f = h - sector;
  const double p = v * (1.0 - s);
  const double q = v * (1.0 - s * f);
  const double t = v * (1.0 - s * (1.0 - f));
  switch (sector) {
    case 0: return {p, t, v};
    case 1: return {p, v, q};
    case 2: return {t, v, p};
    case 3: return {v, q, p};
    case 4: return {v, p, t};
    default: return {q, p, v};
  }
}

double hue_distance(double a, double b) {
  double d = std::fmod(std::abs(a - b), 256.0);
  return std::min(d, 256.0 - d);
}

// Inverse of the standard normal CDF: P. J. Acklam's rational approximation
// (relative error below 1.2e-9), enough for a noise table.
double inverse_normal_cdf(double p) {
  static constexpr double a[] = {-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                                 1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
  static constexpr double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                                 6.680131188771972e+01,  -1.328068155288572e+01};
  static constexpr double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                                 -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
  static constexpr double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                                 3.754408661907416e+00};
  constexpr double p_low = 0.02425;
  if (p < p_low) {
    const double q = std::sqrt(-2.0 * std::log(p));
    return (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
           ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
  }
  if (p > 1.0 - p_low) return -inverse_normal_cdf(1.0 - p);
  const double q = p - 0.5;
  const double r = q * q;
  return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
         (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0);
}

// One camera of the rig, seen from the left camera frame: the right camera is
// the left one shifted by the baseline along x.
struct CameraView {
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
  int width = 0, height = 0;
  double x_shift = 0.0;

  Vec3 from_leftcam(const Vec3& p_in_leftcam) const {
    return {p_in_leftcam.x() - x_shift, p_in_leftcam.y(), p_in_leftcam.z()};
  }
  // Pixel ray through (u, v) with z = 1.
  Vec3 ray(double u, double v) const { return {(u - cx) / fx, (v - cy) / fy, 1.0}; }
};

struct PixelBox {
  int u0 = 0, v0 = 0, u1 = -1, v1 = -1;  // inclusive
  bool empty() const { return u1 < u0 || v1 < v0; }
};

// The pixels the axis-aligned box [lo, hi] (camera frame) can cover. A box
// reaching to or behind the camera plane gets the whole image: the per-pixel
// ray tests then decide.
PixelBox project_box(const CameraView& cam, const Vec3& lo, const Vec3& hi) {
  PixelBox box;
  if (hi.z() <= 1e-4) return box;  // entirely behind the camera
  if (lo.z() <= 1e-4) {
    box.u0 = 0;
    box.v0 = 0;
    box.u1 = cam.width - 1;
    box.v1 = cam.height - 1;
    return box;
  }
  // A box in front of the camera projects inside the hull of its corners.
  double u_min = std::numeric_limits<double>::infinity(), u_max = -u_min, v_min = u_min, v_max = -u_min;
  for (int k = 0; k < 8; ++k) {
    const double x = (k & 1) ? hi.x() : lo.x();
    const double y = (k & 2) ? hi.y() : lo.y();
    const double z = (k & 4) ? hi.z() : lo.z();
    const double u = cam.fx * x / z + cam.cx;
    const double v = cam.fy * y / z + cam.cy;
    u_min = std::min(u_min, u);
    u_max = std::max(u_max, u);
    v_min = std::min(v_min, v);
    v_max = std::max(v_max, v);
  }
  box.u0 = static_cast<int>(std::max(0.0, std::floor(u_min)));
  box.v0 = static_cast<int>(std::max(0.0, std::floor(v_min)));
  box.u1 = static_cast<int>(std::min(static_cast<double>(cam.width - 1), std::ceil(u_max)));
  box.v1 = static_cast<int>(std::min(static_cast<double>(cam.height - 1), std::ceil(v_max)));
  return box;
}

struct DiscCoverage {
  double unoccluded = 0.0;  // sum of coverage, ignoring what hides the disc
  double drawn = 0.0;       // sum of drawn coverage
  double su = 0.0;          // coverage-weighted sums of drawn sample positions
  double sv = 0.0;
};

// How much of pixel (x, y) the perspective image of a flat disc (centre c,
// unit normal n, radius r, camera frame) covers: the share of its 4x4 samples
// inside, their mean offset from the pixel centre, and the depth of the
// pixel's ray on the disc's plane. Pixels well inside or well outside skip the
// supersampling. False when the pixel is not covered at all.
struct DiscPixel {
  double inside = 0.0;
  double off_u = 0.0, off_v = 0.0;
  double z = 0.0;
};
bool disc_pixel(const CameraView& cam, const Vec3& c, const Vec3& n, double n_dot_c, double r, double r2,
                double inv_f, int x, int y, DiscPixel& out) {
  const Vec3 d = cam.ray(x, y);
  const double denom = n.dot(d);
  if (std::abs(denom) < 1e-9) return false;  // edge-on
  out.z = n_dot_c / denom;                   // depth of the ray's hit on the disc's plane
  if (!(out.z > 1e-4)) return false;
  const double rho = (out.z * d - c).norm();
  // Half a pixel diagonal, measured on the disc's plane (stretched by obliquity).
  const double footprint = 0.75 * out.z * inv_f * d.squaredNorm() / std::abs(denom);
  out.off_u = out.off_v = 0.0;
  if (rho <= r - footprint) {
    out.inside = 1.0;
    return true;
  }
  if (rho >= r + footprint) return false;
  int hits = 0;
  for (int sy = 0; sy < 4; ++sy) {
    for (int sx = 0; sx < 4; ++sx) {
      const double ou = -0.375 + 0.25 * sx;
      const double ov = -0.375 + 0.25 * sy;
      const Vec3 ds = cam.ray(x + ou, y + ov);
      const double dn = n.dot(ds);
      if (std::abs(dn) < 1e-12) continue;
      if (((n_dot_c / dn) * ds - c).squaredNorm() <= r2) {
        ++hits;
        out.off_u += ou;
        out.off_v += ov;
      }
    }
  }
  if (hits == 0) return false;
  out.inside = hits / 16.0;
  out.off_u /= hits;
  out.off_v /= hits;
  return true;
}

// Draws the perspective image of a flat disc (centre c, unit normal n,
// radius r, camera frame) in one colour, blending each pixel by the share of
// its 4x4 samples inside the disc. Pixels well inside or well outside skip
// the supersampling. hidden(x, y, z) says whether the disc's point at depth z
// on pixel (x, y) is behind something already drawn; on_drawn(x, y, z,
// coverage) is called for each pixel drawn.
template <class Hidden, class OnDrawn>
DiscCoverage draw_disc(cv::Mat& img, const CameraView& cam, const Vec3& c, const Vec3& n, double r,
                       const cv::Vec3d& bgr, const Hidden& hidden, const OnDrawn& on_drawn) {
  DiscCoverage cov;
  const PixelBox box = project_box(cam, c - Vec3::Constant(r), c + Vec3::Constant(r));
  if (box.empty()) return cov;
  const double n_dot_c = n.dot(c);
  const double inv_f = std::max(1.0 / cam.fx, 1.0 / cam.fy);
  const double r2 = r * r;
  for (int y = box.v0; y <= box.v1; ++y) {
    auto* row = img.ptr<cv::Vec3b>(y);
    for (int x = box.u0; x <= box.u1; ++x) {
      DiscPixel px_on;
      if (!disc_pixel(cam, c, n, n_dot_c, r, r2, inv_f, x, y, px_on)) continue;
      const double inside = px_on.inside, off_u = px_on.off_u, off_v = px_on.off_v, z = px_on.z;
      cov.unoccluded += inside;
      if (hidden(x, y, z)) continue;
      cov.drawn += inside;
      cov.su += inside * (x + off_u);
      cov.sv += inside * (y + off_v);
      cv::Vec3b& px = row[x];
      for (int ch = 0; ch < 3; ++ch) {
        px[ch] = cv::saturate_cast<std::uint8_t>((1.0 - inside) * px[ch] + inside * bgr[ch]);
      }
      on_drawn(x, y, z, inside);
    }
  }
  return cov;
}

// One position of a marker over its exposure: centre and unit normal in the
// camera frame, diffuse colour and its share of the exposure.
struct MarkerPose {
  Vec3 c = Vec3::Zero();
  Vec3 n = Vec3::UnitZ();
  cv::Vec3d bgr;
  double weight = 1.0;
};

// A Blinn-Phong highlight on a domed marker: light direction (unit, camera
// frame), peak strength (fraction of full scale; 0: none), shininess and the
// dome's sphere radius (>= the disc's radius).
struct MarkerGloss {
  Vec3 light = Vec3::UnitZ();
  double strength = 0.0;
  double shininess = 1.0;
  double dome_radius = 1.0;
};

// Draws a marker disc as draw_disc does, but integrated over the exposure:
// coverage and colour are accumulated over its poses (weights summing to 1)
// in `acc`, then blended into the image once, so a moving marker leaves a
// smear of partial coverage. With one pose of weight 1 and no gloss it draws
// exactly what draw_disc draws. hidden(x, y, z) as for draw_disc (only what
// was drawn before this marker); on_drawn(x, y, z_nearest, coverage) for each
// pixel drawn, after blending. *peak gets the strongest specular term drawn.
template <class Hidden, class OnDrawn>
DiscCoverage draw_marker(cv::Mat& img, const CameraView& cam, std::span<const MarkerPose> poses, double r,
                         const MarkerGloss& gloss, std::vector<double>& acc, double& peak, const Hidden& hidden,
                         const OnDrawn& on_drawn) {
  DiscCoverage cov;
  peak = 0.0;
  PixelBox all;
  bool any = false;
  for (const MarkerPose& mp : poses) {
    const PixelBox b = project_box(cam, mp.c - Vec3::Constant(r), mp.c + Vec3::Constant(r));
    if (b.empty()) continue;
    if (!any) {
      all = b;
      any = true;
    } else {
      all.u0 = std::min(all.u0, b.u0);
      all.v0 = std::min(all.v0, b.v0);
      all.u1 = std::max(all.u1, b.u1);
      all.v1 = std::max(all.v1, b.v1);
    }
  }
  if (!any) return cov;
  const int bw = all.u1 - all.u0 + 1;
  const int bh = all.v1 - all.v0 + 1;
  constexpr int kStride = 5;  // coverage, b, g, r, nearest depth
  acc.assign(static_cast<std::size_t>(bw) * static_cast<std::size_t>(bh) * kStride, 0.0);
  for (std::size_t i = 4; i < acc.size(); i += kStride) acc[i] = std::numeric_limits<double>::infinity();
  const double inv_f = std::max(1.0 / cam.fx, 1.0 / cam.fy);
  const double r2 = r * r;
  const double dome2 = gloss.dome_radius * gloss.dome_radius;
  for (const MarkerPose& mp : poses) {
    const PixelBox box = project_box(cam, mp.c - Vec3::Constant(r), mp.c + Vec3::Constant(r));
    if (box.empty()) continue;
    const Vec3& c = mp.c;
    const Vec3& n = mp.n;
    const double w = mp.weight;
    const double n_dot_c = n.dot(c);
    const bool lit = gloss.strength > 0.0 && n.dot(gloss.light) > 0.0;
    for (int y = box.v0; y <= box.v1; ++y) {
      double* arow = acc.data() + static_cast<std::size_t>(y - all.v0) * bw * kStride;
      for (int x = box.u0; x <= box.u1; ++x) {
        DiscPixel px_on;
        if (!disc_pixel(cam, c, n, n_dot_c, r, r2, inv_f, x, y, px_on)) continue;
        const double inside = px_on.inside, off_u = px_on.off_u, off_v = px_on.off_v, z = px_on.z;
        const Vec3 d = cam.ray(x, y);
        const double wi = w * inside;
        cov.unoccluded += wi;
        if (hidden(x, y, z)) continue;
        cov.drawn += wi;
        cov.su += wi * (x + off_u);
        cov.sv += wi * (y + off_v);
        double* a = arow + static_cast<std::size_t>(x - all.u0) * kStride;
        double spec = 0.0;
        if (lit) {
          // The dome over this point of the disc: its normal, and the
          // bisector of the directions to the light and to the camera.
          const Vec3 q = z * d;
          const Vec3 off = q - c;
          const Vec3 n_dome = (off + n * std::sqrt(std::max(dome2 - off.squaredNorm(), 0.0))).normalized();
          const Vec3 h = (gloss.light - q.normalized()).normalized();
          const double nh = n_dome.dot(h);
          if (nh > 0.0) spec = gloss.strength * std::pow(nh, gloss.shininess);
          peak = std::max(peak, spec);
        }
        a[0] += wi;
        for (int ch = 0; ch < 3; ++ch) a[1 + ch] += wi * (mp.bgr[ch] + 255.0 * spec);
        a[4] = std::min(a[4], z);
      }
    }
  }
  for (int y = all.v0; y <= all.v1; ++y) {
    auto* row = img.ptr<cv::Vec3b>(y);
    const double* arow = acc.data() + static_cast<std::size_t>(y - all.v0) * bw * kStride;
    for (int x = all.u0; x <= all.u1; ++x) {
      const double* a = arow + static_cast<std::size_t>(x - all.u0) * kStride;
      if (!(a[0] > 0.0)) continue;
      cv::Vec3b& px = row[x];
      for (int ch = 0; ch < 3; ++ch) {
        px[ch] = cv::saturate_cast<std::uint8_t>((1.0 - a[0]) * px[ch] + a[1 + ch]);
      }
      on_drawn(x, y, a[4], a[0]);
    }
  }
  return cov;
}

// Ray (origin at the camera, unit direction rd) against a capsule: distance
// along the ray to the first hit and the outward normal there, or false.
// Inigo Quilez's closed form (https://iquilezles.org/articles/intersectors/).
bool ray_capsule(const Vec3& rd, const Vec3& pa, const Vec3& pb, double ra, double& t_hit, Vec3& normal) {
  const Vec3 ba = pb - pa;
  const Vec3 oa = -pa;
  const double baba = ba.dot(ba);
  const double bard = ba.dot(rd);
  const double baoa = ba.dot(oa);
  const double rdoa = rd.dot(oa);
  const double oaoa = oa.dot(oa);
  const double a = baba - bard * bard;
  if (baba > 1e-18 && a > 1e-12 * baba) {
    const double b = baba * rdoa - baoa * bard;
    const double c = baba * oaoa - baoa * baoa - ra * ra * baba;
    const double h = b * b - a * c;
    if (h < 0.0) return false;
    const double t = (-b - std::sqrt(h)) / a;
    const double y = baoa + t * bard;
    if (y > 0.0 && y < baba) {
      if (t <= 0.0) return false;
      t_hit = t;
      normal = (t * rd - (pa + ba * (y / baba))) / ra;
      return true;
    }
  }
  // The end caps: the nearer sphere hit of the two.
  bool hit = false;
  for (const Vec3* centre : {&pa, &pb}) {
    const Vec3 oc = -*centre;
    const double b = rd.dot(oc);
    const double c = oc.dot(oc) - ra * ra;
    const double h = b * b - c;
    if (h <= 0.0) continue;
    const double t = -b - std::sqrt(h);
    if (t > 0.0 && (!hit || t < t_hit)) {
      hit = true;
      t_hit = t;
      normal = (t * rd - *centre) / ra;
    }
  }
  return hit;
}

}  // namespace

StereoSimOptions StereoImageSimOptions::default_visibility() {
  StereoSimOptions o;
  o.pixel_noise_px = 0.0;
  o.area_noise_fraction = 0.0;
  o.shuffle = false;
  // Draw small blobs too, so the detector's own size filter is what decides.
  o.min_area_px2 = 8.0;
  // A forearm makes the picture a hand and not a floating palm; the detection
  // simulator then hides markers behind it as well.
  o.forearm_length_m = 0.22;
  return o;
}

Status StereoImageSimOptions::validate() const {
  auto bad = [](const std::string& what) {
    return make_error(Errc::invalid_argument, "stereo image simulator options: " + what);
  };
  if (auto st = visibility.validate(); !st) return st.error().with_context("stereo image simulator options: visibility");
  if (visibility.pixel_noise_px != 0.0 || visibility.area_noise_fraction != 0.0 || visibility.shuffle) {
    return bad(
        "visibility.pixel_noise_px and visibility.area_noise_fraction must be 0 and visibility.shuffle off: in "
        "images the pixels carry the noise (use pixel_noise_dn and blur_sigma_px)");
  }
  if (!finite_in(pixel_noise_dn, 0.0, 64.0)) return bad("pixel_noise_dn must be in [0, 64] (8-bit steps)");
  if (!finite_in(blur_sigma_px, 0.0, 10.0)) return bad("blur_sigma_px must be in [0, 10] (pixels)");
  if (!finite_in(exposure_jitter, 0.0, 0.5)) return bad("exposure_jitter must be in [0, 0.5]");
  if (!finite_in(background_depth_m, 0.2, 100.0)) return bad("background_depth_m must be in [0.2, 100] (metres)");
  if (!T_world_head_rest.p.allFinite() || !(std::abs(T_world_head_rest.q.norm() - 1.0) < 1e-6)) {
    return bad("T_world_head_rest needs a finite position and a unit quaternion");
  }
  if (clutter_shapes < 0 || clutter_shapes > 100000) return bad("clutter_shapes must be in [0, 100000]");
  if (clutter_marker_coloured_shapes < 0 || clutter_marker_coloured_shapes > 10000) {
    return bad("clutter_marker_coloured_shapes must be in [0, 10000]");
  }
  for (double c : clutter_hue_clearance) {
    if (!finite_in(c, 0.0, 64.0)) return bad("clutter_hue_clearance values must be in [0, 64] (HSV_FULL steps)");
  }
  if (distractors < 0 || distractors > 10000) return bad("distractors must be in [0, 10000]");
  if (!(std::isfinite(distractor_min_diameter_m) && std::isfinite(distractor_max_diameter_m) &&
        distractor_min_diameter_m > 0.0 && distractor_min_diameter_m <= distractor_max_diameter_m)) {
    return bad("distractor diameters need 0 < distractor_min_diameter_m <= distractor_max_diameter_m (metres)");
  }
  for (double v : skin_bgr) {
    if (!finite_in(v, 0.0, 255.0)) return bad("skin_bgr values must be in [0, 255]");
  }
  if (!light_dir_in_leftcam.allFinite() || !(light_dir_in_leftcam.norm() > 1e-9)) {
    return bad("light_dir_in_leftcam must be a finite, non-zero direction");
  }
  if (!finite_in(ambient, 0.0, 1.0)) return bad("ambient must be in [0, 1]");
  if (!(std::isfinite(marker_saturation) && marker_saturation > 0.0 && marker_saturation <= 1.0)) {
    return bad("marker_saturation must be in (0, 1]");
  }
  if (!(std::isfinite(marker_value) && marker_value > 0.0 && marker_value <= 255.0)) {
    return bad("marker_value must be in (0, 255]");
  }
  if (!finite_in(marker_brightness_jitter, 0.0, 0.9)) return bad("marker_brightness_jitter must be in [0, 0.9]");
  if (!finite_in(marker_hue_jitter, 0.0, 20.0)) return bad("marker_hue_jitter must be in [0, 20] (HSV_FULL steps)");
  // Camera realism.
  if (!finite_in(exposure_s, 1e-5, 0.1)) return bad("exposure_s must be in [1e-5, 0.1] (seconds)");
  if (!finite_in(timestamp_in_exposure, 0.0, 1.0)) {
    return bad("timestamp_in_exposure must be in [0, 1] (0: the stamp is the start of the exposure, 1: its end)");
  }
  if (!finite_in(sensor_gain_dn_per_e, 0.0, 10.0))
    return bad("sensor_gain_dn_per_e must be in [0, 10] (DN per electron)");
  if (!finite_in(light_level, 0.01, 100.0))
    return bad("light_level must be in [0.01, 100] (relative to an indoor room)");
  if (sensor_noise && !(effective_read_noise_dn() <= 64.0 && effective_gain_dn_per_e() <= 10.0)) {
    return bad(
        "sensor_noise: pixel_noise_dn and sensor_gain_dn_per_e times gain_ratio() (4 ms / exposure_s / "
        "light_level) must stay within 64 DN and 10 DN per electron");
  }
  if (!finite_in(residual_k1_sigma, 0.0, 0.1)) return bad("residual_k1_sigma must be in [0, 0.1]");
  if (!finite_in(residual_k2_sigma, 0.0, 0.1)) return bad("residual_k2_sigma must be in [0, 0.1]");
  if (!finite_in(residual_p_sigma, 0.0, 0.01)) return bad("residual_p_sigma must be in [0, 0.01]");
  if (!finite_in(vignetting, 0.0, 1.0)) return bad("vignetting must be in [0, 1]");
  if (!finite_in(illumination_gradient, 0.0, 0.9)) return bad("illumination_gradient must be in [0, 0.9]");
  if (!finite_in(colour_cast, 0.0, 0.5)) return bad("colour_cast must be in [0, 0.5]");
  if (!finite_in(specular, 0.0, 4.0)) return bad("specular must be in [0, 4] (fraction of full scale)");
  if (!finite_in(specular_shininess, 1.0, 100000.0)) return bad("specular_shininess must be in [1, 100000]");
  if (!finite_in(marker_gloss_spread, 0.0, 1.0)) return bad("marker_gloss_spread must be in [0, 1]");
  if (!finite_in(marker_dome_radius_m, 1e-4, 10.0)) return bad("marker_dome_radius_m must be in [1e-4, 10] (metres)");
  return Status::success();
}

void StereoImageSimOptions::switch_off_camera_realism() {
  motion_blur = false;
  sensor_noise = false;
  lens_residual = false;
  vignetting = 0.0;
  illumination_gradient = 0.0;
  colour_cast = 0.0;
  specular = 0.0;
}

StereoImageSimOptions StereoImageSimOptions::idealised() {
  StereoImageSimOptions o;
  o.switch_off_camera_realism();
  return o;
}

Eigen::Vector2d LensResidual::distort_px(const PinholeCamera& k, double u_px, double v_px) const {
  const double x = (u_px - k.cx_px) / k.fx_px;
  const double y = (v_px - k.cy_px) / k.fy_px;
  const double r2 = x * x + y * y;
  const double radial = 1.0 + k1 * r2 + k2 * r2 * r2;
  const double xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
  const double yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
  return {k.fx_px * xd + k.cx_px, k.fy_px * yd + k.cy_px};
}

Eigen::Vector2d LensResidual::undistort_px(const PinholeCamera& k, double u_px, double v_px) const {
  const double xd = (u_px - k.cx_px) / k.fx_px;
  const double yd = (v_px - k.cy_px) / k.fy_px;
  double x = xd, y = yd;
  for (int it = 0; it < 20; ++it) {
    const double r2 = x * x + y * y;
    const double radial = 1.0 + k1 * r2 + k2 * r2 * r2;
    const double dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
    const double dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
    const double x_next = (xd - dx) / radial;
    const double y_next = (yd - dy) / radial;
    const bool converged = std::abs(x_next - x) + std::abs(y_next - y) < 1e-13;
    x = x_next;
    y = y_next;
    if (converged) break;
  }
  return {k.fx_px * x + k.cx_px, k.fy_px * y + k.cy_px};
}

double LensResidual::corner_shift_px(const PinholeCamera& k) const {
  double worst = 0.0;
  for (double u : {0.0, k.width_px - 1.0}) {
    for (double v : {0.0, k.height_px - 1.0}) {
      worst = std::max(worst, (distort_px(k, u, v) - Eigen::Vector2d(u, v)).norm());
    }
  }
  return worst;
}

std::string StereoImageSimOptions::describe() const {
  char buf[2048];
  std::snprintf(buf, sizeof buf,
                "noise=%.2fDN blur=%.2fpx exposure_jitter=%.3f background=%.2fm clutter=%s(%d shapes, %d "
                "marker-coloured, hue clearance %.0f/%.0f/%.0f/%.0f) distractors=%d(%.0f-%.0fmm) skin_bgr=(%.0f,%.0f,%.0f) "
                "ambient=%.2f marker(s=%.2f v=%.0f brightness+-%.2f hue+-%.1f) seed=%llu visibility={%s}",
                pixel_noise_dn, blur_sigma_px, exposure_jitter, background_depth_m, clutter ? "on" : "off",
                clutter_shapes, clutter_marker_coloured_shapes, clutter_hue_clearance[0], clutter_hue_clearance[1],
                clutter_hue_clearance[2], clutter_hue_clearance[3], distractors,
                distractor_min_diameter_m * 1e3, distractor_max_diameter_m * 1e3, skin_bgr[0], skin_bgr[1],
                skin_bgr[2], ambient, marker_saturation, marker_value, marker_brightness_jitter, marker_hue_jitter,
                static_cast<unsigned long long>(seed), visibility.describe().c_str());
  std::string out = buf;
  std::snprintf(buf, sizeof buf,
                " camera_realism={motion_blur=%s exposure=%.2fms stamp_in_exposure=%.2f sensor_noise=%s(gain "
                "%.3fDN/e- light_level %.2f: %.3fDN/e-, read %.2fDN) lens_residual=%s(k1 sigma %.4g, k2 sigma %.4g, p "
                "sigma %.4g) vignetting=%.2f illumination_gradient=%.2f colour_cast=%.3f specular=%.2f(shininess %.0f, "
                "gloss spread %.2f, dome %.1fmm)}",
                motion_blur ? "on" : "off", exposure_s * 1e3, timestamp_in_exposure, sensor_noise ? "on" : "off",
                sensor_gain_dn_per_e, light_level, effective_gain_dn_per_e(), effective_read_noise_dn(),
                lens_residual ? "on" : "off", residual_k1_sigma, residual_k2_sigma, residual_p_sigma, vignetting,
                illumination_gradient, colour_cast, specular, specular_shininess, marker_gloss_spread,
                marker_dome_radius_m * 1e3);
  return out + buf;
}

Result<StereoImageSimulator> StereoImageSimulator::create(const ImuGloveDescription& glove, const HandShape& shape,
                                                          StereoImageSimOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  StereoSimOptions vis = options.visibility;
  vis.seed = options.seed;
  auto markers = StereoMarkerSimulator::create(glove, shape, vis);
  if (!markers) return markers.error();
  return create(std::move(*markers), options);
}

Result<StereoImageSimulator> StereoImageSimulator::create(StereoMarkerSimulator markers,
                                                          StereoImageSimOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  const StereoSimOptions& mo = markers.options();
  if (mo.pixel_noise_px != 0.0 || mo.area_noise_fraction != 0.0 || mo.shuffle) {
    return make_error(Errc::invalid_argument,
                      "stereo image simulator: the marker simulator must have pixel_noise_px = 0, "
                      "area_noise_fraction = 0 and shuffle off (the images carry the noise); build it with "
                      "StereoImageSimOptions::default_visibility()");
  }
  const PinholeCamera& k = markers.rig().camera;
  if (k.width_px <= 0 || k.height_px <= 0 || k.width_px > 16384 || k.height_px > 16384 || !(k.fx_px > 0.0) ||
      !(k.fy_px > 0.0) || !std::isfinite(k.cx_px) || !std::isfinite(k.cy_px)) {
    return make_error(Errc::invalid_argument,
                      "stereo image simulator: the camera needs an image size in 1..16384 and positive focal "
                      "lengths");
  }
  if (!(markers.rig().baseline_m > 0.0)) {
    return make_error(Errc::invalid_argument, "stereo image simulator: the rig needs baseline_m > 0");
  }
  return StereoImageSimulator(std::move(markers), options);
}

StereoImageSimulator::StereoImageSimulator(StereoMarkerSimulator markers, StereoImageSimOptions options)
    : markers_(std::move(markers)), options_(options) {
  // Noise table: the standard normal at 65536 evenly spaced quantiles, so
  // one 64-bit draw gives four normal deviates (tails cut at about 4.3 sigma).
  normal_table_.resize(65536);
  for (std::size_t i = 0; i < normal_table_.size(); ++i) {
    normal_table_[i] = static_cast<float>(inverse_normal_cdf((static_cast<double>(i) + 0.5) / 65536.0));
  }
  // Per-marker look: the fabric's brightness and the dye's hue vary from
  // marker to marker, but not over time.
  Rng look(mix_seed(options_.seed, kMarkerLookStream));
  for (const PlacedMarker& m : markers_.markers()) {
    const double brightness = 1.0 + options_.marker_brightness_jitter * (2.0 * look.uniform01() - 1.0);
    const double hue = marker_hue_code(m.hue) + options_.marker_hue_jitter * (2.0 * look.uniform01() - 1.0);
    marker_brightness_.push_back(brightness);
    marker_hue_codes_.push_back(static_cast<std::uint8_t>(static_cast<int>(std::lround(hue) + 256) % 256));
  }
  build_wall();
  build_distractors();
  build_camera_look();
}

void StereoImageSimulator::build_camera_look() {
  const StereoImageSimOptions& o = options_;
  const PinholeCamera& k = rig().camera;
  // Per-session draws, each from its own stream and drawn whether or not its
  // effect is on, so switching one off changes no other.
  {
    Rng rng(mix_seed(o.seed, kLensStream));
    for (LensResidual& lens : look_.lens) {
      lens.k1 = o.residual_k1_sigma * rng.normal();
      lens.k2 = o.residual_k2_sigma * rng.normal();
      lens.p1 = o.residual_p_sigma * rng.normal();
      lens.p2 = o.residual_p_sigma * rng.normal();
      if (!o.lens_residual) lens = LensResidual{};
    }
  }
  {
    Rng rng(mix_seed(o.seed, kColourCastStream));
    const double b = 1.0 + o.colour_cast * (2.0 * rng.uniform01() - 1.0);
    const double r = 1.0 + o.colour_cast * (2.0 * rng.uniform01() - 1.0);
    look_.colour_gain_bgr = {b, 1.0, r};
  }
  {
    Rng rng(mix_seed(o.seed, kGradientStream));
    look_.gradient_angle_rad = rng.uniform(0.0, 2.0 * std::numbers::pi);
  }
  {
    Rng rng(mix_seed(o.seed, kGlossStream));
    look_.marker_gloss.clear();
    for (std::size_t i = 0; i < markers_.markers().size(); ++i) {
      look_.marker_gloss.push_back(1.0 - o.marker_gloss_spread * rng.uniform01());
    }
  }

  // The spatial light factor: vignetting (relative illumination
  // 1 - v (1 - cos^4 theta), theta off the optical axis) times the gradient.
  if (o.vignetting > 0.0 || o.illumination_gradient > 0.0) {
    const double gx = std::cos(look_.gradient_angle_rad) / (0.5 * k.width_px);
    const double gy = std::sin(look_.gradient_angle_rad) / (0.5 * k.height_px);
    for (cv::Mat& map : light_map_) {
      map.create(k.height_px, k.width_px, CV_32F);
      for (int y = 0; y < k.height_px; ++y) {
        float* row = map.ptr<float>(y);
        const double yn = (y - k.cy_px) / k.fy_px;
        for (int x = 0; x < k.width_px; ++x) {
          const double xn = (x - k.cx_px) / k.fx_px;
          const double cos2 = 1.0 / (1.0 + xn * xn + yn * yn);
          const double vig = 1.0 - o.vignetting * (1.0 - cos2 * cos2);
          const double ramp = std::max(0.0, 1.0 + o.illumination_gradient * ((x - k.cx_px) * gx + (y - k.cy_px) * gy));
          row[x] = static_cast<float>(vig * ramp);
        }
      }
    }
  }

  // The lens residual: each image pixel (distorted) samples the ideal image
  // where the ideal pinhole put the point it shows.
  for (std::size_t c = 0; c < 2; ++c) {
    if (look_.lens[c].zero()) continue;
    cv::Mat mx(k.height_px, k.width_px, CV_32F), my(k.height_px, k.width_px, CV_32F);
    for (int y = 0; y < k.height_px; ++y) {
      float* rx = mx.ptr<float>(y);
      float* ry = my.ptr<float>(y);
      for (int x = 0; x < k.width_px; ++x) {
        const Eigen::Vector2d src = look_.lens[c].undistort_px(k, x, y);
        rx[x] = static_cast<float>(src.x());
        ry[x] = static_cast<float>(src.y());
      }
    }
    cv::convertMaps(mx, my, lens_map1_[c], lens_map2_[c], CV_16SC2);
  }

  // Sensor noise: sigma per 8-bit level, sqrt(K S + read^2) (EMVA 1288).
  const double gain = o.effective_gain_dn_per_e();
  const double read = o.effective_read_noise_dn();
  for (std::size_t i = 0; i < noise_sigma_.size(); ++i) {
    noise_sigma_[i] = static_cast<float>(std::sqrt(gain * static_cast<double>(i) + read * read));
  }
}

void StereoImageSimulator::build_wall() {
  const StereoImageSimOptions& o = options_;
  const PinholeCamera& k = rig().camera;
  const double depth = o.background_depth_m;
  // One texel is about one image pixel at rest; the wall is twice the resting
  // view in each direction, so head sway stays on it.
  wall_texel_m_ = depth / k.fx_px;
  const int tex_w = 2 * k.width_px;
  const int tex_h = static_cast<int>(std::lround(2.0 * k.height_px * k.fx_px / k.fy_px));
  const Pose T_world_leftcam_rest = o.T_world_head_rest * rig().T_head_leftcam;
  const Vec3 centre_in_world = T_world_leftcam_rest * Vec3(0.0, 0.0, depth);
  const Vec3 x_axis = T_world_leftcam_rest.q * Vec3::UnitX();
  const Vec3 y_axis = T_world_leftcam_rest.q * Vec3::UnitY();
  T_world_wall_.q = T_world_leftcam_rest.q;
  T_world_wall_.p = centre_in_world - wall_texel_m_ * (0.5 * (tex_w - 1) * x_axis + 0.5 * (tex_h - 1) * y_axis);

  Rng rng(mix_seed(o.seed, kWallStream));
  if (!o.clutter) {
    wall_.create(tex_h, tex_w, CV_8UC3);
    wall_.setTo(cv::Scalar(128, 128, 128));
    return;
  }
  // Smooth, muted colour variation (paint, light falloff), then shapes.
  cv::Mat coarse(12, 20, CV_8UC3);
  for (int y = 0; y < coarse.rows; ++y) {
    for (int x = 0; x < coarse.cols; ++x) {
      const cv::Vec3d c = hsv_full_to_bgr(rng.uniform(0.0, 256.0), rng.uniform(0.0, 0.3), rng.uniform(50.0, 200.0));
      coarse.at<cv::Vec3b>(y, x) = cv::Vec3b(cv::saturate_cast<std::uint8_t>(c[0]), cv::saturate_cast<std::uint8_t>(c[1]),
                                             cv::saturate_cast<std::uint8_t>(c[2]));
    }
  }
  cv::resize(coarse, wall_, cv::Size(tex_w, tex_h), 0.0, 0.0, cv::INTER_CUBIC);

  // Saturated clutter hues: away from every glove hue by the clearance.
  const std::array<double, 4> glove_hues = {
      static_cast<double>(marker_hue_code(MarkerHue::red)), static_cast<double>(marker_hue_code(MarkerHue::yellow)),
      static_cast<double>(marker_hue_code(MarkerHue::green)), static_cast<double>(marker_hue_code(MarkerHue::blue))};
  auto clear_of_glove_hues = [&](double hue) {
    for (std::size_t h = 0; h < kMarkerHueCount; ++h) {
      if (hue_distance(hue, glove_hues[h]) < o.clutter_hue_clearance[h]) return false;
    }
    return true;
  };
  auto clutter_colour = [&]() -> cv::Scalar {
    const double kind = rng.uniform01();
    double hue = rng.uniform(0.0, 256.0);
    double s, v;
    if (kind < 0.55) {  // desaturated: greys, beiges, pastels
      s = rng.uniform(0.0, 0.3);
      v = rng.uniform(40.0, 250.0);
    } else if (kind < 0.8) {  // dark, any hue
      s = rng.uniform(0.0, 1.0);
      v = rng.uniform(5.0, 60.0);
    } else {  // saturated, between the glove hues
      for (int tries = 0; tries < 64 && !clear_of_glove_hues(hue); ++tries) hue = rng.uniform(0.0, 256.0);
      if (!clear_of_glove_hues(hue)) s = 0.2;  // no hue left: desaturate instead
      else s = rng.uniform(0.5, 1.0);
      v = rng.uniform(80.0, 250.0);
    }
    const cv::Vec3d c = hsv_full_to_bgr(hue, s, v);
    return {c[0], c[1], c[2]};
  };
  auto point = [&](double margin) {
    return cv::Point(static_cast<int>(rng.uniform(-margin, tex_w + margin)),
                     static_cast<int>(rng.uniform(-margin, tex_h + margin)));
  };
  for (int i = 0; i < o.clutter_shapes; ++i) {
    const cv::Scalar colour = clutter_colour();
    const double kind = rng.uniform01();
    const cv::Point p = point(50.0);
    if (kind < 0.3) {
      const cv::Point q = p + cv::Point(static_cast<int>(rng.uniform(-250.0, 250.0)),
                                        static_cast<int>(rng.uniform(-250.0, 250.0)));
      cv::rectangle(wall_, p, q, colour, rng.uniform01() < 0.8 ? cv::FILLED : 1 + static_cast<int>(rng.below(6)),
                    cv::LINE_AA);
    } else if (kind < 0.55) {
      const cv::Point q = p + cv::Point(static_cast<int>(rng.uniform(-500.0, 500.0)),
                                        static_cast<int>(rng.uniform(-500.0, 500.0)));
      cv::line(wall_, p, q, colour, 1 + static_cast<int>(rng.below(8)), cv::LINE_AA);
    } else if (kind < 0.8) {
      const cv::Size axes(5 + static_cast<int>(rng.below(150)), 5 + static_cast<int>(rng.below(150)));
      cv::ellipse(wall_, p, axes, rng.uniform(0.0, 180.0), 0.0, 360.0, colour,
                  rng.uniform01() < 0.7 ? cv::FILLED : 1 + static_cast<int>(rng.below(5)), cv::LINE_AA);
    } else {
      std::array<cv::Point, 6> poly;
      const int n = 3 + static_cast<int>(rng.below(4));
      const double radius = rng.uniform(20.0, 200.0);
      for (int v = 0; v < n; ++v) {
        const double a = 2.0 * std::numbers::pi * (v + rng.uniform(0.0, 0.8)) / n;
        const double rr = radius * rng.uniform(0.4, 1.0);
        poly[static_cast<std::size_t>(v)] =
            p + cv::Point(static_cast<int>(rr * std::cos(a)), static_cast<int>(rr * std::sin(a)));
      }
      cv::fillConvexPoly(wall_, poly.data(), n, colour, cv::LINE_AA);
    }
  }
  // Marker-coloured shapes no marker could be: long thin bars and big panels.
  for (int i = 0; i < o.clutter_marker_coloured_shapes; ++i) {
    const double hue = glove_hues[rng.below(4)];
    const cv::Vec3d c = hsv_full_to_bgr(hue, rng.uniform(0.7, 1.0), rng.uniform(150.0, 240.0));
    const cv::Scalar colour(c[0], c[1], c[2]);
    const cv::Point p = point(0.0);
    if (rng.uniform01() < 0.5) {
      const double a = rng.uniform(0.0, std::numbers::pi);
      const double len = rng.uniform(150.0, 600.0);
      const cv::Point q = p + cv::Point(static_cast<int>(len * std::cos(a)), static_cast<int>(len * std::sin(a)));
      cv::line(wall_, p, q, colour, 2 + static_cast<int>(rng.below(4)), cv::LINE_AA);
    } else {
      const cv::Point q = p + cv::Point(150 + static_cast<int>(rng.below(250)), 150 + static_cast<int>(rng.below(250)));
      cv::rectangle(wall_, p, q, colour, cv::FILLED, cv::LINE_AA);
    }
  }
  // Fine texture (fabric, paper, plaster grain), fixed on the wall.
  for (int y = 0; y < wall_.rows; ++y) {
    auto* row = wall_.ptr<std::uint8_t>(y);
    for (int x = 0; x < 3 * wall_.cols; x += 4) {
      std::uint64_t bits = rng.next_u64();
      for (int j = 0; j < 4 && x + j < 3 * wall_.cols; ++j, bits >>= 16) {
        row[x + j] = cv::saturate_cast<std::uint8_t>(row[x + j] + 6.0f * normal_table_[bits & 0xffff]);
      }
    }
  }
}

void StereoImageSimulator::build_distractors() {
  const StereoImageSimOptions& o = options_;
  Rng rng(mix_seed(o.seed, kDistractorStream));
  const PinholeCamera& k = rig().camera;
  // Spread over the wall's part in the resting view, with a tenth beyond it.
  const double half_w_texels = 0.55 * k.width_px;
  const double half_h_texels = 0.55 * k.height_px * k.fx_px / k.fy_px;
  const double cx_tex = 0.5 * (wall_.cols - 1);
  const double cy_tex = 0.5 * (wall_.rows - 1);
  const Vec3 normal_in_world = T_world_wall_.q * Vec3(0.0, 0.0, -1.0);  // toward the resting camera
  for (int i = 0; i < o.distractors; ++i) {
    Distractor d;
    d.hue = static_cast<MarkerHue>(rng.below(kMarkerHueCount));
    const double hue = marker_hue_code(d.hue) + o.marker_hue_jitter * (2.0 * rng.uniform01() - 1.0);
    d.hue_code = static_cast<std::uint8_t>(static_cast<int>(std::lround(hue) + 256) % 256);
    d.diameter_m = rng.uniform(o.distractor_min_diameter_m, o.distractor_max_diameter_m);
    d.value = rng.uniform(150.0, 235.0);
    d.normal_in_world = normal_in_world;
    // Discs do not overlap (a few tries), so each one's truth is its own
    // disc and not a mix of two.
    for (int attempt = 0; attempt < 200; ++attempt) {
      const double tx = cx_tex + rng.uniform(-half_w_texels, half_w_texels);
      const double ty = cy_tex + rng.uniform(-half_h_texels, half_h_texels);
      d.p_in_world = T_world_wall_ * Vec3(tx * wall_texel_m_, ty * wall_texel_m_, 0.0);
      const bool clear = std::none_of(distractors_.begin(), distractors_.end(), [&](const Distractor& e) {
        return (e.p_in_world - d.p_in_world).norm() < 0.5 * (e.diameter_m + d.diameter_m) + 0.01;
      });
      if (clear) break;
    }
    distractors_.push_back(d);
  }
}

void StereoImageSimulator::render(const HandPose& hand, const Pose& T_world_head, TimeNs t_ns, StereoImageFrame& out,
                                  StereoImageTruth* truth, const std::vector<bool>* hidden_markers,
                                  std::span<const Vec3> skin_offsets) {
  const StereoImageSimOptions& o = options_;
  const StereoRig& rig = markers_.rig();
  const PinholeCamera& k = rig.camera;
  StereoGroundTruth& gt = truth ? truth->markers : scratch_truth_;
  const StereoFrame frame = markers_.simulate(hand, T_world_head, t_ns, &gt, skin_offsets);
  if (hidden_markers) {
    for (std::size_t c = 0; c < 2; ++c) {
      std::erase_if(gt.cameras[c], [&](const MarkerTruth& mt) {
        if (mt.marker >= hidden_markers->size() || !(*hidden_markers)[mt.marker]) return false;
        gt.visibility[c][mt.marker] = MarkerVisibility::occluded;
        return true;
      });
    }
  }
  out.time_ns = t_ns;
  out.dropped = frame.dropped;
  if (truth) {
    for (std::size_t c = 0; c < 2; ++c) {
      truth->drawn[c].clear();
      truth->distractors[c].clear();
    }
  }
  if (frame.dropped) {
    for (auto& img : out.images) img.release();
    return;
  }

  const Pose T_world_lc = markers_.T_world_leftcam(T_world_head);
  const Pose T_lc_world = T_world_lc.inverse();
  const Vec3 light = o.light_dir_in_leftcam.normalized();
  auto shade = [&](const Vec3& normal_in_cam) { return o.ambient + (1.0 - o.ambient) * std::max(0.0, normal_in_cam.dot(light)); };

  // The hand in the left camera frame: capsules and marker normals.
  HandCapsules caps;
  if (hand.active) caps = hand_capsules(hand, markers_.options().forearm_length_m);
  std::array<Vec3, HandCapsules::kMax> cap_a{}, cap_b{};
  std::array<std::uint8_t, HandCapsules::kMax> cap_body{};
  // Motion over the exposure, [t - stamp * exposure, t + (1 - stamp) * exposure]:
  // a point on a segment moves with the segment's linear and angular
  // velocity (world frame); the head is taken as still during it.
  const bool moving = o.motion_blur && hand.active && hand.has_velocity;
  const double dt_start = -o.timestamp_in_exposure * o.exposure_s;
  const double dt_mid = moving ? dt_start + 0.5 * o.exposure_s : 0.0;
  auto velocity_at = [&](HandJoint segment, const Vec3& p_in_world) -> Vec3 {
    const std::size_t j = index_of(segment);
    return hand.linear_velocity_in_world[j] +
           hand.angular_velocity_in_world[j].cross(p_in_world - hand.T_world_joint[j].p);
  };
  for (std::size_t i = 0; i < caps.count; ++i) {
    Vec3 a = caps.capsules[i].a;
    Vec3 b = caps.capsules[i].b;
    if (moving) {  // the hand's skin where it is at mid-exposure (not smeared)
      a += dt_mid * velocity_at(caps.owner[i], caps.capsules[i].a);
      b += dt_mid * velocity_at(caps.owner[i], caps.capsules[i].b);
    }
    cap_a[i] = T_lc_world * a;
    cap_b[i] = T_lc_world * b;
    cap_body[i] = static_cast<std::uint8_t>(index_of(body_of(caps.owner[i])));
  }
  const bool mirror = hand.hand != markers_.markers_hand();
  const double exposure = [&] {
    Rng rng(mix_seed(mix_seed(o.seed, kExposureStream), static_cast<std::uint64_t>(t_ns)));
    return 1.0 + o.exposure_jitter * (2.0 * rng.uniform01() - 1.0);
  }();
  MarkerGloss gloss;
  gloss.light = light;
  gloss.strength = o.specular;
  gloss.shininess = o.specular_shininess;
  std::array<MarkerPose, kMaxBlurSteps> poses;
  std::size_t pose_count = 0;

  for (std::size_t c = 0; c < 2; ++c) {
    CameraView cam;
    cam.fx = k.fx_px;
    cam.fy = k.fy_px;
    cam.cx = k.cx_px;
    cam.cy = k.cy_px;
    cam.width = k.width_px;
    cam.height = k.height_px;
    cam.x_shift = (c == 1) ? rig.baseline_m : 0.0;
    cv::Mat& img = out.images[c];
    img.create(k.height_px, k.width_px, CV_8UC3);

    // 1. The wall, through the homography texel -> pixel of its plane.
    const Pose T_cam_world = Pose{Quat::Identity(), Vec3(-cam.x_shift, 0.0, 0.0)} * T_lc_world;
    const Mat3 R = T_cam_world.q.toRotationMatrix();
    const Vec3 col_x = wall_texel_m_ * (R * (T_world_wall_.q * Vec3::UnitX()));
    const Vec3 col_y = wall_texel_m_ * (R * (T_world_wall_.q * Vec3::UnitY()));
    const Vec3 col_o = T_cam_world * T_world_wall_.p;
    Mat3 Kmat;
    Kmat << k.fx_px, 0.0, k.cx_px, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 1.0;
    Mat3 M;
    M.col(0) = col_x;
    M.col(1) = col_y;
    M.col(2) = col_o;
    const Mat3 H = Kmat * M;
    cv::Matx33d Hcv;
    for (int r = 0; r < 3; ++r) {
      for (int q = 0; q < 3; ++q) Hcv(r, q) = H(r, q);
    }
    cv::warpPerspective(wall_, img, Hcv, img.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);

    // 2. The hand: per-pixel ray casting into a depth buffer.
    depth_.create(k.height_px, k.width_px, CV_32F);
    owner_.create(k.height_px, k.width_px, CV_8U);
    depth_.setTo(std::numeric_limits<float>::infinity());
    owner_.setTo(kNoBody);
    for (std::size_t i = 0; i < caps.count; ++i) {
      const Vec3 pa = cam.from_leftcam(cap_a[i]);
      const Vec3 pb = cam.from_leftcam(cap_b[i]);
      const double ra = caps.capsules[i].radius_m;
      if (!(ra > 0.0)) continue;
      const PixelBox box = project_box(cam, pa.cwiseMin(pb) - Vec3::Constant(ra), pa.cwiseMax(pb) + Vec3::Constant(ra));
      for (int y = box.v0; y <= box.v1; ++y) {
        auto* row = img.ptr<cv::Vec3b>(y);
        float* zrow = depth_.ptr<float>(y);
        std::uint8_t* orow = owner_.ptr<std::uint8_t>(y);
        for (int x = box.u0; x <= box.u1; ++x) {
          const Vec3 d = cam.ray(x, y);
          const double inv_len = 1.0 / d.norm();
          const Vec3 rd = d * inv_len;
          double t = 0.0;
          Vec3 normal;
          if (!ray_capsule(rd, pa, pb, ra, t, normal)) continue;
          const double z = t * rd.z();
          if (!(z < zrow[x])) continue;
          zrow[x] = static_cast<float>(z);
          orow[x] = cap_body[i];
          const double s = shade(normal);
          row[x] = cv::Vec3b(cv::saturate_cast<std::uint8_t>(o.skin_bgr[0] * s),
                             cv::saturate_cast<std::uint8_t>(o.skin_bgr[1] * s),
                             cv::saturate_cast<std::uint8_t>(o.skin_bgr[2] * s));
        }
      }
    }

    // 3. Distractors on the wall, wherever the hand does not cover them.
    for (std::size_t i = 0; i < distractors_.size(); ++i) {
      const Distractor& dis = distractors_[i];
      const Vec3 p_lc = T_lc_world * dis.p_in_world;
      const Vec3 p_cam = cam.from_leftcam(p_lc);
      const Vec3 n_cam = T_lc_world.q * dis.normal_in_world;
      if (!(p_cam.z() > 0.0) || !(n_cam.dot(-p_cam) > 0.0)) continue;  // behind the camera or seen from behind
      const cv::Vec3d bgr = hsv_full_to_bgr(dis.hue_code, o.marker_saturation, dis.value);
      const DiscCoverage cov = draw_disc(img, cam, p_cam, n_cam, 0.5 * dis.diameter_m, bgr,
                                         [&](int x, int y, double) { return owner_.at<std::uint8_t>(y, x) != kNoBody; },
                                         [](int, int, double, double) {});
      if (truth && cov.drawn > 0.0) {
        DistractorImageTruth dt;
        dt.distractor = i;
        dt.hue = dis.hue;
        dt.u_px = cam.fx * p_cam.x() / p_cam.z() + cam.cx;
        dt.v_px = cam.fy * p_cam.y() / p_cam.z() + cam.cy;
        dt.area_px2 = cov.drawn;
        dt.unoccluded_area_px2 = cov.unoccluded;
        dt.p_in_leftcam = p_lc;
        truth->distractors[c].push_back(dt);
      }
    }

    // 4. The markers the detection simulator reports visible in this camera,
    // nearest first, each entering the depth buffer where it covers most of a
    // pixel, so a marker hides the parts of farther ones behind it. A marker
    // is drawn over its own rigid body's skin (it sits on it; the capsules
    // only approximate the skin) but behind another body that is nearer by
    // more than the occlusion offset.
    const double tolerance_m = markers_.options().occlusion_offset_m;
    const std::vector<MarkerTruth>& seen = gt.cameras[c];
    draw_order_.resize(seen.size());
    for (std::size_t i = 0; i < seen.size(); ++i) draw_order_[i] = i;
    std::stable_sort(draw_order_.begin(), draw_order_.end(), [&](std::size_t a, std::size_t b) {
      return seen[a].p_in_leftcam.z() < seen[b].p_in_leftcam.z();
    });
    if (truth) truth->drawn[c].resize(seen.size());
    for (std::size_t i : draw_order_) {
      const MarkerTruth& mt = seen[i];
      const PlacedMarker& m = markers_.markers()[mt.marker];
      const Vec3 n_seg =
          mirror ? Vec3(-m.normal_in_segment.x(), m.normal_in_segment.y(), m.normal_in_segment.z()) : m.normal_in_segment;
      const Vec3 n_cam = T_lc_world.q * (hand.joint(m.segment).q * n_seg);
      const Vec3 p_cam = cam.from_leftcam(mt.p_in_leftcam);
      const std::uint8_t own = static_cast<std::uint8_t>(index_of(body_of(m.segment)));
      const std::uint8_t self = static_cast<std::uint8_t>(kFirstMarkerId + std::min<std::size_t>(mt.marker, 190));
      auto colour = [&](const Vec3& normal) {
        const double value = o.marker_value * marker_brightness_[mt.marker] * shade(normal);
        return hsv_full_to_bgr(marker_hue_codes_[mt.marker], o.marker_saturation, value);
      };
      // Its poses over the exposure: one, at t, when nothing moves; else
      // enough sub-exposure positions to keep them kBlurStepPx apart.
      const double r = 0.5 * m.diameter_m;
      Eigen::Vector2d blur = Eigen::Vector2d::Zero();
      pose_count = 0;
      if (!moving) {
        poses[pose_count++] = {p_cam, n_cam, colour(n_cam), 1.0};
      } else {
        const Vec3 v_cam = T_lc_world.q * velocity_at(m.segment, T_world_lc * mt.p_in_leftcam);
        const Vec3 w_cam = T_lc_world.q * hand.angular_velocity_in_world[index_of(m.segment)];
        auto project = [&](const Vec3& p) {
          return Eigen::Vector2d(cam.fx * p.x() / p.z() + cam.cx, cam.fy * p.y() / p.z() + cam.cy);
        };
        const Vec3 p0 = p_cam + dt_start * v_cam;
        const Vec3 p1 = p_cam + (dt_start + o.exposure_s) * v_cam;
        if (p0.z() > 1e-3 && p1.z() > 1e-3) blur = project(p1) - project(p0);
        const int steps = std::clamp(static_cast<int>(std::ceil(blur.norm() / kBlurStepPx)), 1, kMaxBlurSteps);
        for (int s = 0; s < steps; ++s) {
          const double dt = dt_start + o.exposure_s * (s + 0.5) / steps;
          const Vec3 n_s = (n_cam + dt * w_cam.cross(n_cam)).normalized();
          poses[pose_count++] = {p_cam + dt * v_cam, n_s, colour(n_s), 1.0 / steps};
        }
      }
      gloss.strength = o.specular * look_.marker_gloss[mt.marker];
      gloss.dome_radius = std::max(o.marker_dome_radius_m, r);
      double peak = 0.0;
      const DiscCoverage cov = draw_marker(
          img, cam, std::span<const MarkerPose>(poses.data(), pose_count), r, gloss, marker_acc_, peak,
          [&](int x, int y, double z) {
            const std::uint8_t body = owner_.at<std::uint8_t>(y, x);
            const float zbuf = depth_.at<float>(y, x);
            if (body == kNoBody || body == own) return false;
            if (body >= kFirstMarkerId) return zbuf < z;  // an earlier, so nearer, marker
            return zbuf < z - tolerance_m;
          },
          [&](int x, int y, double z, double coverage) {
            if (coverage >= 0.5) {
              owner_.at<std::uint8_t>(y, x) = self;
              depth_.at<float>(y, x) = static_cast<float>(z);
            }
          });
      if (truth) {
        MarkerImageTruth& it = truth->drawn[c][i];
        it.marker = mt.marker;
        it.hue = m.hue;
        it.hue_code = marker_hue_codes_[mt.marker];
        it.u_px = mt.u_px;
        it.v_px = mt.v_px;
        it.area_px2 = cov.drawn;
        it.unoccluded_area_px2 = cov.unoccluded;
        it.u_drawn_px = cov.drawn > 0.0 ? cov.su / cov.drawn : mt.u_px;
        it.v_drawn_px = cov.drawn > 0.0 ? cov.sv / cov.drawn : mt.v_px;
        it.normal_in_leftcam = n_cam;
        it.blur_u_px = blur.x();
        it.blur_v_px = blur.y();
        it.highlight = peak;
      }
    }

    // 5. The camera: exposure and the light's spatial and colour factors,
    // the lens residual, optics blur, sensor noise.
    if (!light_map_[c].empty() || o.colour_cast > 0.0) {
      const cv::Mat& light_map = light_map_[c];
      const float gain[3] = {static_cast<float>(exposure * look_.colour_gain_bgr[0]),
                             static_cast<float>(exposure * look_.colour_gain_bgr[1]),
                             static_cast<float>(exposure * look_.colour_gain_bgr[2])};
      for (int y = 0; y < img.rows; ++y) {
        std::uint8_t* row = img.ptr<std::uint8_t>(y);
        const float* lrow = light_map.empty() ? nullptr : light_map.ptr<float>(y);
        for (int x = 0; x < img.cols; ++x) {
          const float f = lrow ? lrow[x] : 1.0f;
          for (int ch = 0; ch < 3; ++ch) {
            row[3 * x + ch] = cv::saturate_cast<std::uint8_t>(row[3 * x + ch] * (f * gain[ch]));
          }
        }
      }
    } else if (o.exposure_jitter > 0.0) {
      img.convertTo(img, -1, exposure);
    }
    if (!lens_map1_[c].empty()) {
      cv::remap(img, blurred_, lens_map1_[c], lens_map2_[c], cv::INTER_LINEAR, cv::BORDER_REPLICATE);
      std::swap(img, blurred_);
    }
    if (o.blur_sigma_px > 0.0) {
      cv::GaussianBlur(img, blurred_, cv::Size(0, 0), o.blur_sigma_px, o.blur_sigma_px, cv::BORDER_REFLECT);
      std::swap(img, blurred_);
    }
    if (o.sensor_noise && noise_sigma_.back() > 0.0f) {
      // Shot and read noise: sigma by the pixel's level, from the same
      // stream of normal deviates as the plain noise below.
      Rng rng(mix_seed(mix_seed(o.seed, kNoiseStream + c), static_cast<std::uint64_t>(t_ns)));
      const int n = 3 * img.cols;
      for (int y = 0; y < img.rows; ++y) {
        std::uint8_t* row = img.ptr<std::uint8_t>(y);
        for (int x = 0; x < n; x += 4) {
          std::uint64_t bits = rng.next_u64();
          const int m = std::min(4, n - x);
          for (int j = 0; j < m; ++j, bits >>= 16) {
            row[x + j] =
                cv::saturate_cast<std::uint8_t>(row[x + j] + noise_sigma_[row[x + j]] * normal_table_[bits & 0xffff]);
          }
        }
      }
    } else if (!o.sensor_noise && o.pixel_noise_dn > 0.0) {
      Rng rng(mix_seed(mix_seed(o.seed, kNoiseStream + c), static_cast<std::uint64_t>(t_ns)));
      const float sigma = static_cast<float>(o.pixel_noise_dn);
      const int n = 3 * img.cols;
      for (int y = 0; y < img.rows; ++y) {
        std::uint8_t* row = img.ptr<std::uint8_t>(y);
        for (int x = 0; x < n; x += 4) {
          std::uint64_t bits = rng.next_u64();
          const int m = std::min(4, n - x);
          for (int j = 0; j < m; ++j, bits >>= 16) {
            row[x + j] = cv::saturate_cast<std::uint8_t>(row[x + j] + sigma * normal_table_[bits & 0xffff]);
          }
        }
      }
    }
  }
}

}  // namespace proprio::sim
