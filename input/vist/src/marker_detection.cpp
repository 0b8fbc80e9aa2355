#include "proprio/vist/marker_detection.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numeric>
#include <semaphore>
#include <thread>
#include <vector>

namespace proprio::vist {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Signed circular difference a - b on the 256-step hue circle, in [-128, 128).
double hue_delta(double a, double b) {
  double d = std::fmod(a - b, 256.0);
  if (d < -128.0) d += 256.0;
  if (d >= 128.0) d -= 256.0;
  return d;
}
// The same for a and b already in [0, 256): no fmod on the hot path.
inline double hue_delta_256(double a, double b) {
  double d = a - b;
  if (d < -128.0) d += 256.0;
  else if (d >= 128.0) d -= 256.0;
  return d;
}

// Full-resolution pixels are kept packed as (y << 16) | x: images are at
// most 16384 pixels wide, and unpacking needs no division.
constexpr std::int32_t pack(int x, int y) { return (y << 16) | x; }
constexpr int unpack_x(std::int32_t p) { return p & 0xffff; }
constexpr int unpack_y(std::int32_t p) { return p >> 16; }

bool finite_in(double x, double lo, double hi) { return std::isfinite(x) && x >= lo && x <= hi; }

// Visit marks of the full-resolution flood fill.
constexpr std::uint8_t kUntested = 0;
constexpr std::uint8_t kFailed = 1;    // failed the current blob's test (reset after each blob)
constexpr std::uint8_t kInBlob = 2;    // counted in the current blob, its row span not grown yet
constexpr std::uint8_t kSpanDone = 3;  // member of a blob (reset after the image)

long long gcd_ll(long long a, long long b) {
  a = std::llabs(a);
  b = std::llabs(b);
  while (b) {
    const long long t = a % b;
    a = b;
    b = t;
  }
  return a;
}

long long cross(const cv::Point& o, const cv::Point& a, const cv::Point& b) {
  return static_cast<long long>(a.x - o.x) * (b.y - o.y) - static_cast<long long>(a.y - o.y) * (b.x - o.x);
}

}  // namespace

void MarkerDetectionStats::add(const MarkerDetectionStats& o) {
  coarse_components += o.coarse_components;
  rejected_coarse_large += o.rejected_coarse_large;
  merged += o.merged;
  no_seed += o.no_seed;
  rejected_small += o.rejected_small;
  rejected_large += o.rejected_large;
  rejected_border += o.rejected_border;
  rejected_solidity += o.rejected_solidity;
  rejected_circularity += o.rejected_circularity;
  accepted += o.accepted;
  for (std::size_t h = 0; h < kMarkerHueCount; ++h) accepted_per_hue[h] += o.accepted_per_hue[h];
}

std::array<HueThreshold, kMarkerHueCount> MarkerDetectorOptions::default_hues() {
  // Centres are the glove hues as the HSV_FULL codes of opencv_hue() (red 0,
  // yellow 43, green 85, blue 171). The windows leave gaps for orange (skin,
  // wood), yellow-green, cyan and purple; green and blue get wider windows
  // because their neighbours are far away and cameras render them less pure.
  return {HueThreshold{MarkerHue::red, 0.0, 12.0, 120.0, 70.0},
          HueThreshold{MarkerHue::yellow, 43.0, 12.0, 120.0, 70.0},
          HueThreshold{MarkerHue::green, 85.0, 18.0, 120.0, 70.0},
          HueThreshold{MarkerHue::blue, 171.0, 20.0, 120.0, 70.0}};
}

Status MarkerDetectorOptions::validate() const {
  auto bad = [](const std::string& what) { return make_error(Errc::invalid_argument, "marker detector options: " + what); };
  for (std::size_t h = 0; h < kMarkerHueCount; ++h) {
    const HueThreshold& t = hues[h];
    const std::string name = "hues[" + std::to_string(h) + "] (" + std::string(to_string(static_cast<MarkerHue>(h))) + ")";
    if (t.hue != static_cast<MarkerHue>(h)) return bad(name + ".hue must be " + std::string(to_string(static_cast<MarkerHue>(h))) + ": hues are in MarkerHue order");
    if (!finite_in(t.hue_center, 0.0, 255.999)) return bad(name + ".hue_center must be in [0, 256) (HSV_FULL steps)");
    if (!finite_in(t.hue_half_width, 0.5, 64.0)) return bad(name + ".hue_half_width must be in [0.5, 64] (HSV_FULL steps)");
    if (!finite_in(t.min_saturation, 1.0, 255.0)) return bad(name + ".min_saturation must be in [1, 255]");
    if (!finite_in(t.min_value, 1.0, 255.0)) return bad(name + ".min_value must be in [1, 255]");
  }
  for (std::size_t a = 0; a < kMarkerHueCount; ++a) {
    for (std::size_t b = a + 1; b < kMarkerHueCount; ++b) {
      const double d = std::abs(hue_delta(hues[a].hue_center, hues[b].hue_center));
      if (d <= hues[a].hue_half_width + hues[b].hue_half_width) {
        return bad("the hue windows of " + std::string(to_string(hues[a].hue)) + " and " +
                   std::string(to_string(hues[b].hue)) + " overlap; narrow hue_half_width so each colour has one hue");
      }
    }
  }
  if (!(std::isfinite(marker_diameter_m) && marker_diameter_m > 0.0 && marker_diameter_m < 1.0)) {
    return bad("marker_diameter_m must be in (0, 1) (metres)");
  }
  if (!(std::isfinite(min_depth_m) && std::isfinite(max_depth_m) && min_depth_m > 0.0 && min_depth_m < max_depth_m)) {
    return bad("depths need 0 < min_depth_m < max_depth_m (metres)");
  }
  if (!finite_in(min_area_factor, 0.0, 1.0)) return bad("min_area_factor must be in [0, 1]");
  if (!finite_in(max_area_factor, 1.0, 100.0)) return bad("max_area_factor must be in [1, 100]");
  if (!finite_in(min_solidity, 0.0, 1.0)) return bad("min_solidity must be in [0, 1]");
  if (!finite_in(min_circularity, 0.0, 1.0)) return bad("min_circularity must be in [0, 1]");
  if (coarse_step != 1 && coarse_step != 2 && coarse_step != 4) return bad("coarse_step must be 1, 2 or 4");
  if (reserve_markers > 100000) return bad("reserve_markers must be at most 100000");
  return Status::success();
}

std::string MarkerDetectorOptions::describe() const {
  std::string s;
  char buf[256];
  for (const HueThreshold& t : hues) {
    std::snprintf(buf, sizeof buf, "%s(h=%.1f+-%.1f s>=%.0f v>=%.0f) ", std::string(to_string(t.hue)).c_str(),
                  t.hue_center, t.hue_half_width, t.min_saturation, t.min_value);
    s += buf;
  }
  std::snprintf(buf, sizeof buf,
                "diameter=%.1fmm depth=%.2f..%.2fm area_factor=%.2f..%.2f solidity>=%.2f circularity>=%.2f "
                "border=%s centroid=%s coarse_step=%d parallel_stereo=%s",
                marker_diameter_m * 1e3, min_depth_m, max_depth_m, min_area_factor, max_area_factor, min_solidity,
                min_circularity, reject_border ? "reject" : "keep", subpixel_weights ? "weighted" : "binary",
                coarse_step, parallel_stereo ? "on" : "off");
  s += buf;
  return s;
}

// A horizontal run of coarse samples of one class: the unit of the coarse
// connected-component labelling (union-find over runs, 8-connected).
struct Run {
  std::int32_t y = 0;   // coarse row
  std::int32_t x0 = 0;  // first and last coarse column, inclusive
  std::int32_t x1 = 0;
  std::int32_t parent = 0;  // union-find; a root is its component's first run in scan order
  std::int32_t next = -1;   // next run of the same component (scan order)
  std::int8_t cls = 0;
};

// Scratch of one image; two of them so left and right can run at once.
struct Worker {
  std::vector<std::uint8_t> coarse_row;  // class + 1 of each sample of one coarse row
  std::vector<Run> runs;
  std::vector<std::int32_t> comp_count;  // per root run: coarse samples in its component
  std::vector<std::int32_t> comp_tail;   // per root run: last run appended to its list
  std::vector<std::uint8_t> visit;    // full resolution: kUntested, kFailed, kInBlob, kSpanDone
  std::vector<std::int32_t> in_blob;  // packed pixels of measured blobs, reset after the image
  std::vector<std::int32_t> failed;   // packed pixels marked kFailed, reset after each blob
  std::vector<std::int32_t> fill_stack;
  std::vector<int> row_min, row_max;  // per image row, x extent of the current blob
  std::vector<cv::Point> hull_pts;    // row extents of the blob, then its hull
  std::vector<cv::Point> hull;
  MarkerDetectionStats stats;
};

struct MarkerDetector::Impl {
  PinholeCamera camera;
  MarkerDetectorOptions options;
  double min_area = 0.0;
  double max_area = 0.0;
  double min_saturation_any = 255.0;  // smallest threshold over the hues: a quick reject
  double min_value_any = 255.0;
  std::vector<std::int8_t> lut;  // 32x32x32 BGR cells -> class or -1 (permissive)
  std::array<float, 256> inv{};  // 1/x, x = 1..255
  std::array<Worker, 2> workers;

  // The helper thread of detect_stereo().
  std::thread helper;
  std::binary_semaphore start{0};
  std::binary_semaphore done{0};
  std::atomic<bool> quit{false};
  const cv::Mat* job_image = nullptr;
  MarkerObservations* job_out = nullptr;
  Status job_status;  // written by the helper before it releases `done`

  ~Impl() {
    if (helper.joinable()) {
      quit.store(true, std::memory_order_relaxed);
      start.release();
      helper.join();
    }
  }

  // Exact test: class of a BGR colour (or -1) and its hue offset from the
  // class centre (HSV_FULL steps).
  int classify(int b, int g, int r, double* hue_offset) const noexcept {
    const int v = std::max(b, std::max(g, r));
    if (v < min_value_any || v == 0) return -1;
    const int mn = std::min(b, std::min(g, r));
    const int diff = v - mn;
    const double s = 255.0 * diff * inv[static_cast<std::size_t>(v)];
    if (s < min_saturation_any || diff == 0) return -1;
    // OpenCV's hue: sector by the largest channel, degrees, then 256/360 steps.
    const double k = 60.0 * inv[static_cast<std::size_t>(diff)];
    double h_deg;
    if (v == r) h_deg = k * (g - b);
    else if (v == g) h_deg = 120.0 + k * (b - r);
    else h_deg = 240.0 + k * (r - g);
    if (h_deg < 0.0) h_deg += 360.0;
    const double code = h_deg * (256.0 / 360.0);
    for (std::size_t h = 0; h < kMarkerHueCount; ++h) {
      const HueThreshold& t = options.hues[h];
      const double d = hue_delta_256(code, t.hue_center);
      if (std::abs(d) <= t.hue_half_width && s >= t.min_saturation && v >= t.min_value) {
        if (hue_offset) *hue_offset = d;
        return static_cast<int>(h);
      }
    }
    return -1;
  }

  void build_lut() {
    lut.assign(32 * 32 * 32, -1);
    for (int bi = 0; bi < 32; ++bi) {
      for (int gi = 0; gi < 32; ++gi) {
        for (int ri = 0; ri < 32; ++ri) {
          // The cell's centre first, then its corners: the first hue found.
          int cls = classify(8 * bi + 4, 8 * gi + 4, 8 * ri + 4, nullptr);
          for (int corner = 0; corner < 8 && cls < 0; ++corner) {
            cls = classify(8 * bi + ((corner & 1) ? 7 : 0), 8 * gi + ((corner & 2) ? 7 : 0),
                           8 * ri + ((corner & 4) ? 7 : 0), nullptr);
          }
          lut[static_cast<std::size_t>((bi << 10) | (gi << 5) | ri)] = static_cast<std::int8_t>(cls);
        }
      }
    }
  }

  void prepare(Worker& w) const {
    const auto n = static_cast<std::size_t>(camera.width_px) * static_cast<std::size_t>(camera.height_px);
    const std::size_t runs = 16384;  // a busy scene has a few thousand; more grow once
    w.coarse_row.assign(static_cast<std::size_t>(camera.width_px), 0);
    w.runs.reserve(runs);
    w.comp_count.reserve(runs);
    w.comp_tail.reserve(runs);
    w.visit.assign(n, kUntested);
    const std::size_t blob_reserve = static_cast<std::size_t>(2.0 * max_area) + 64;
    w.in_blob.reserve(blob_reserve * options.reserve_markers / 4 + 1024);
    w.failed.reserve(blob_reserve);
    w.fill_stack.reserve(blob_reserve);
    w.row_min.assign(static_cast<std::size_t>(camera.height_px), std::numeric_limits<int>::max());
    w.row_max.assign(static_cast<std::size_t>(camera.height_px), std::numeric_limits<int>::min());
    w.hull_pts.reserve(2 * static_cast<std::size_t>(camera.height_px));
    w.hull.reserve(4 * static_cast<std::size_t>(camera.height_px) + 2);
  }

  Status check(const cv::Mat& img, const char* which) const {
    auto bad = [&](const std::string& what) {
      return make_error(Errc::invalid_argument, std::string("marker detection (") + which + " image): " + what);
    };
    if (img.empty()) return bad("the image is empty (no frame arrived?)");
    if (img.dims != 2 || img.type() != CV_8UC3) {
      return bad("expected an 8-bit, 3-channel BGR image (CV_8UC3), got type " + std::to_string(img.type()) +
                 " with " + std::to_string(img.channels()) + " channels; convert with cv::cvtColor first");
    }
    if (img.cols != camera.width_px || img.rows != camera.height_px) {
      return bad("expected " + std::to_string(camera.width_px) + "x" + std::to_string(camera.height_px) +
                 " pixels (the calibrated camera), got " + std::to_string(img.cols) + "x" + std::to_string(img.rows));
    }
    return Status::success();
  }

  Status run(Worker& w, const cv::Mat& img, MarkerObservations& out, const char* which) const;
  void measure_blob(Worker& w, const cv::Mat& img, int seed_x, int seed_y, int cls, MarkerObservations& out) const;
};

Status MarkerDetector::Impl::run(Worker& w, const cv::Mat& img, MarkerObservations& out, const char* which) const {
  out.markers.clear();
  w.stats = MarkerDetectionStats{};
  if (auto st = check(img, which); !st) return st;
  const int step = options.coarse_step;
  const int cw = (camera.width_px + step - 1) / step;
  const int ch = (camera.height_px + step - 1) / step;

  // 1. Coarse classification through the table, straight into runs, each
  //    joined to the runs of the row above that it touches (8-connected).
  std::vector<Run>& runs = w.runs;
  runs.clear();
  auto find = [&runs](std::int32_t i) {
    while (runs[static_cast<std::size_t>(i)].parent != i) {
      Run& r = runs[static_cast<std::size_t>(i)];
      r.parent = runs[static_cast<std::size_t>(r.parent)].parent;  // path halving
      i = r.parent;
    }
    return i;
  };
  const std::int8_t* table = lut.data();
  std::uint8_t* classes = w.coarse_row.data();  // class + 1 per sample; 0: none
  // Samples whose 4-byte read stays inside the row (x <= W - 2).
  const int fast_samples = camera.width_px >= 2 ? std::min(cw, (camera.width_px - 2) / step + 1) : 0;
  std::size_t above_begin = 0, above_end = 0;
  for (int cy = 0; cy < ch; ++cy) {
    // Branch-free table look-ups first; the runs come from a scan of the
    // result, which skips empty stretches eight samples at a time.
    const std::uint8_t* row = img.ptr<std::uint8_t>(cy * step);
    const int stride = 3 * step;
    // One 4-byte load per sample (B, G, R and a byte of the next pixel) while
    // that stays inside the row; byte order fixed by the shifts below.
    int cx = 0;
    // Unrolled: independent look-ups overlap (about 10 % faster here).
#pragma GCC unroll 4
    for (; cx < fast_samples; ++cx) {
      std::uint32_t v;
      std::memcpy(&v, row + cx * stride, sizeof v);
      if constexpr (std::endian::native == std::endian::little) {
        classes[cx] = static_cast<std::uint8_t>(table[((v & 0xf8u) << 7) | ((v >> 6) & 0x3e0u) | ((v >> 19) & 0x1fu)] + 1);
      } else {
        const std::uint8_t* p = row + cx * stride;
        classes[cx] = static_cast<std::uint8_t>(table[((p[0] >> 3) << 10) | ((p[1] >> 3) << 5) | (p[2] >> 3)] + 1);
      }
    }
    for (; cx < cw; ++cx) {
      const std::uint8_t* p = row + cx * stride;
      classes[cx] = static_cast<std::uint8_t>(table[((p[0] >> 3) << 10) | ((p[1] >> 3) << 5) | (p[2] >> 3)] + 1);
    }
    const std::size_t row_begin = runs.size();
    std::size_t above = above_begin;
    cx = 0;
    while (cx < cw) {
      if (cx + 8 <= cw) {
        std::uint64_t word;
        std::memcpy(&word, classes + cx, sizeof word);
        if (word == 0) {
          cx += 8;
          continue;
        }
      }
      const std::uint8_t label = classes[cx];
      if (label == 0) {
        ++cx;
        continue;
      }
      const int x0 = cx;
      while (cx < cw && classes[cx] == label) ++cx;
      const int x1 = cx - 1;
      const auto cls = static_cast<std::int8_t>(label - 1);
      const auto self = static_cast<std::int32_t>(runs.size());
      runs.push_back(Run{cy, x0, x1, self, -1, cls});
      // Runs above are sorted by x: skip those ending left of this one.
      while (above < above_end && runs[above].x1 < x0 - 1) ++above;
      for (std::size_t j = above; j < above_end && runs[j].x0 <= x1 + 1; ++j) {
        if (runs[j].cls != cls) continue;
        const std::int32_t a = find(static_cast<std::int32_t>(j));
        const std::int32_t b = find(self);
        if (a == b) continue;
        // The earlier run stays root, so a root is its component's first run.
        if (a < b) runs[static_cast<std::size_t>(b)].parent = a;
        else runs[static_cast<std::size_t>(a)].parent = b;
      }
    }
    above_begin = row_begin;
    above_end = runs.size();
  }

  // 2. Components: sizes and run lists, in scan order.
  const std::size_t nr = runs.size();
  w.comp_count.assign(nr, 0);
  w.comp_tail.resize(nr);
  for (std::size_t i = 0; i < nr; ++i) {
    const std::int32_t r = find(static_cast<std::int32_t>(i));
    runs[i].parent = r;
    w.comp_count[static_cast<std::size_t>(r)] += runs[i].x1 - runs[i].x0 + 1;
    if (static_cast<std::int32_t>(i) == r) {
      w.comp_tail[i] = r;
    } else {
      runs[static_cast<std::size_t>(w.comp_tail[static_cast<std::size_t>(r)])].next = static_cast<std::int32_t>(i);
      w.comp_tail[static_cast<std::size_t>(r)] = static_cast<std::int32_t>(i);
    }
  }

  // 3. Each component, in scan order of its first run. The table is
  //    permissive, so some samples (edges, blends) fail the exact test.
  const double coarse_limit = 4.0 * max_area / (step * step);
  for (std::size_t i = 0; i < nr; ++i) {
    if (runs[i].parent != static_cast<std::int32_t>(i)) continue;
    ++w.stats.coarse_components;
    if (static_cast<double>(w.comp_count[i]) > coarse_limit) {
      ++w.stats.rejected_coarse_large;
      continue;
    }
    // Every sample of the component that passes the exact test and is not
    // inside a blob measured already seeds a blob: one coarse component can
    // hold several blobs (two markers joined by blended samples).
    const int cls = runs[i].cls;
    bool any_pass = false, any_new = false;
    for (std::int32_t k = static_cast<std::int32_t>(i); k >= 0; k = runs[static_cast<std::size_t>(k)].next) {
      const Run& r = runs[static_cast<std::size_t>(k)];
      const int y = r.y * step;
      const std::uint8_t* row = img.ptr<std::uint8_t>(y);
      const std::uint8_t* vrow = w.visit.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(camera.width_px);
      for (int cx = r.x0; cx <= r.x1; ++cx) {
        const int x = cx * step;
        const std::uint8_t* p = row + 3 * x;
        if (classify(p[0], p[1], p[2], nullptr) != cls) continue;
        any_pass = true;
        if (vrow[x] == kSpanDone) continue;
        any_new = true;
        measure_blob(w, img, x, y, cls, out);
      }
    }
    if (!any_pass) ++w.stats.no_seed;
    else if (!any_new) ++w.stats.merged;
  }

  // Reset the marks for the next image (only what was touched).
  const auto W = static_cast<std::size_t>(camera.width_px);
  for (std::int32_t p : w.in_blob) {
    w.visit[static_cast<std::size_t>(unpack_y(p)) * W + static_cast<std::size_t>(unpack_x(p))] = kUntested;
  }
  w.in_blob.clear();
  w.stats.accepted = out.markers.size();
  return Status::success();
}

void MarkerDetector::Impl::measure_blob(Worker& w, const cv::Mat& img, int seed_x, int seed_y, int cls,
                                        MarkerObservations& out) const {
  const int W = camera.width_px;
  const int H = camera.height_px;
  auto pixel_class = [&](int x, int y, double* hue_offset) {
    const std::uint8_t* p = img.ptr<std::uint8_t>(y) + 3 * x;
    return classify(p[0], p[1], p[2], hue_offset);
  };
  auto at = [&](int x, int y) { return static_cast<std::size_t>(y) * static_cast<std::size_t>(W) + static_cast<std::size_t>(x); };

  const int sx = seed_x;
  const int sy = seed_y;

  // Scanline flood fill (8-connected) with the exact test. Each pixel is
  // classified once and counted the moment it passes; spans are then grown
  // along rows and the rows above and below scanned for new spans, so memory
  // is walked along rows. Sums are integers (the hue offsets aside), so the
  // result does not depend on the fill order.
  const double cap = 1.5 * max_area + 16.0;
  long long n = 0, sum_x = 0, sum_y = 0;
  double sum_hue = 0.0;
  int y_lo = sy, y_hi = sy;
  bool touches_border = false;
  bool capped = false;
  w.fill_stack.clear();
  w.failed.clear();
  const std::size_t blob_begin = w.in_blob.size();
  std::uint8_t* visit = w.visit.data();
  auto test = [&](int x, int y) {
    double hue_offset = 0.0;
    if (pixel_class(x, y, &hue_offset) != cls) {
      visit[at(x, y)] = kFailed;
      w.failed.push_back(pack(x, y));
      return false;
    }
    visit[at(x, y)] = kInBlob;
    w.in_blob.push_back(pack(x, y));
    ++n;
    sum_x += x;
    sum_y += y;
    sum_hue += hue_offset;
    auto& rmin = w.row_min[static_cast<std::size_t>(y)];
    auto& rmax = w.row_max[static_cast<std::size_t>(y)];
    rmin = std::min(rmin, x);
    rmax = std::max(rmax, x);
    y_lo = std::min(y_lo, y);
    y_hi = std::max(y_hi, y);
    if (x == 0 || y == 0 || x == W - 1 || y == H - 1) touches_border = true;
    // Far too large: stop (its pixels stay marked, so later seeds in it are skipped).
    if (static_cast<double>(n) > cap) capped = true;
    return true;
  };
  test(sx, sy);  // passes: the caller checked
  w.fill_stack.push_back(pack(sx, sy));
  while (!w.fill_stack.empty() && !capped) {
    const std::int32_t packed = w.fill_stack.back();
    w.fill_stack.pop_back();
    const int y = unpack_y(packed);
    std::uint8_t* vrow = visit + at(0, y);
    int xl = unpack_x(packed);
    if (vrow[xl] != kInBlob) continue;  // already in a grown span
    // Grow the span through pixels counted already and untested ones that pass.
    int xr = xl;
    while (!capped && xl > 0 && (vrow[xl - 1] == kInBlob || (vrow[xl - 1] == kUntested && test(xl - 1, y)))) --xl;
    while (!capped && xr < W - 1 && (vrow[xr + 1] == kInBlob || (vrow[xr + 1] == kUntested && test(xr + 1, y)))) ++xr;
    std::fill(vrow + xl, vrow + xr + 1, kSpanDone);
    // The rows above and below, one pixel wider (8-connected): each run of
    // passing pixels there starts a span.
    for (int ny = y - 1; ny <= y + 1 && !capped; ny += 2) {
      if (ny < 0 || ny >= H) continue;
      const std::uint8_t* nrow = visit + at(0, ny);
      bool in_run = false;
      for (int nx = std::max(0, xl - 1); nx <= std::min(W - 1, xr + 1) && !capped; ++nx) {
        const std::uint8_t v = nrow[nx];
        const bool pass = v == kUntested ? test(nx, ny) : v == kInBlob;
        if (pass && !in_run) w.fill_stack.push_back(pack(nx, ny));
        in_run = pass;
      }
    }
  }
  // Settle this blob: every pixel of it done, so a later blob (of another
  // hue) never takes its pixels for its own; forget the failed tests.
  for (std::size_t k = blob_begin; k < w.in_blob.size(); ++k) {
    visit[at(unpack_x(w.in_blob[k]), unpack_y(w.in_blob[k]))] = kSpanDone;
  }
  for (std::int32_t p : w.failed) visit[at(unpack_x(p), unpack_y(p))] = kUntested;

  // The row extents, in (y, x) order, are all a convex hull needs.
  w.hull_pts.clear();
  for (int y = y_lo; y <= y_hi; ++y) {
    auto& rmin = w.row_min[static_cast<std::size_t>(y)];
    auto& rmax = w.row_max[static_cast<std::size_t>(y)];
    if (rmin <= rmax) {
      w.hull_pts.emplace_back(rmin, y);
      if (rmax != rmin) w.hull_pts.emplace_back(rmax, y);
    }
    rmin = std::numeric_limits<int>::max();
    rmax = std::numeric_limits<int>::min();
  }

  // Filters, cheapest first.
  const double area = static_cast<double>(n);
  if (capped || area > max_area) {
    ++w.stats.rejected_large;
    return;
  }
  if (area < min_area) {
    ++w.stats.rejected_small;
    return;
  }
  if (touches_border && options.reject_border) {
    ++w.stats.rejected_border;
    return;
  }
  // Convex hull of the pixel centres (Andrew's monotone chain; the points
  // are already sorted by y, then x).
  w.hull.clear();
  const std::size_t np = w.hull_pts.size();
  if (np <= 2) {
    w.hull.assign(w.hull_pts.begin(), w.hull_pts.end());
  } else {
    w.hull.resize(2 * np);
    std::size_t k = 0;
    for (std::size_t i = 0; i < np; ++i) {
      while (k >= 2 && cross(w.hull[k - 2], w.hull[k - 1], w.hull_pts[i]) <= 0) --k;
      w.hull[k++] = w.hull_pts[i];
    }
    for (std::size_t i = np - 1, t = k + 1; i-- > 0;) {
      while (k >= t && cross(w.hull[k - 2], w.hull[k - 1], w.hull_pts[i]) <= 0) --k;
      w.hull[k++] = w.hull_pts[i];
    }
    w.hull.resize(k - 1);
  }
  // Twice the hull's area, its perimeter and lattice points on its boundary.
  long long twice_area = 0;
  long long boundary = 0;
  double perimeter = 0.0;
  const std::size_t nh = w.hull.size();
  for (std::size_t i = 0; i < nh && nh >= 2; ++i) {
    const cv::Point& a = w.hull[i];
    const cv::Point& b = w.hull[(i + 1) % nh];
    twice_area += static_cast<long long>(a.x) * b.y - static_cast<long long>(b.x) * a.y;
    boundary += gcd_ll(b.x - a.x, b.y - a.y);
    perimeter += std::hypot(static_cast<double>(b.x - a.x), static_cast<double>(b.y - a.y));
  }
  // (Two hull points: a segment, walked there and back: twice its length.)
  twice_area = std::llabs(twice_area);
  // Pick's theorem: lattice points inside or on a lattice polygon = A + B/2 + 1.
  const double hull_points = 0.5 * static_cast<double>(twice_area) + 0.5 * static_cast<double>(boundary) + 1.0;
  const double solidity = area / std::max(hull_points, 1.0);
  if (solidity < options.min_solidity) {
    ++w.stats.rejected_solidity;
    return;
  }
  // Circularity of the hull grown by half a pixel (each pixel a unit-diameter
  // disc): A' = A + P/2 + pi/4, P' = P + pi. One pixel is a disc (1), a
  // digital disc is about 1, a line of pixels tends to 0.
  const double hull_area = 0.5 * static_cast<double>(twice_area);
  const double grown_area = hull_area + 0.5 * perimeter + 0.25 * kPi;
  const double grown_perimeter = perimeter + kPi;
  const double circularity = 4.0 * kPi * grown_area / (grown_perimeter * grown_perimeter);
  if (circularity < options.min_circularity) {
    ++w.stats.rejected_circularity;
    return;
  }

  // Mean hue and centroid.
  const HueThreshold& t = options.hues[static_cast<std::size_t>(cls)];
  double hue = std::fmod(t.hue_center + sum_hue / area, 256.0);
  if (hue < 0.0) hue += 256.0;
  double u = static_cast<double>(sum_x) / area;
  double v = static_cast<double>(sum_y) / area;
  if (options.subpixel_weights) {
    // Each pixel weighted by how much of the marker's colour it holds: its
    // chroma along the blob's hue (opponent axes, linear in the colour, so a
    // blend of the marker with a grey fraction 1 - a has a times the
    // marker's value), ramped from the blob's weakest pixel (about the
    // threshold) to the mean of its interior pixels. Edge pixels then count
    // by their coverage instead of all or nothing, which takes out most of
    // the thresholded mask's digitisation error without reaching into the
    // background.
    const double theta = hue * (2.0 * kPi / 256.0);
    const double ca = std::cos(theta);
    const double sa = std::sin(theta) * (0.5 * std::sqrt(3.0));
    auto along = [&](std::int32_t packed) {
      const std::uint8_t* p = img.ptr<std::uint8_t>(unpack_y(packed)) + 3 * unpack_x(packed);
      return ca * (p[2] - 0.5 * (p[0] + p[1])) + sa * (p[1] - p[0]);
    };
    double lo = std::numeric_limits<double>::infinity(), hi_sum = 0.0, hi_max = -lo;
    std::size_t hi_n = 0;
    for (std::size_t k = blob_begin; k < w.in_blob.size(); ++k) {
      const std::int32_t packed = w.in_blob[k];
      const double a = along(packed);
      lo = std::min(lo, a);
      hi_max = std::max(hi_max, a);
      const int x = unpack_x(packed);
      const int y = unpack_y(packed);
      // Interior: its 4 neighbours are in a blob (this one: classes are exclusive
      // and blobs of one class are not adjacent).
      if (x > 0 && y > 0 && x < W - 1 && y < H - 1 && w.visit[at(x - 1, y)] == kSpanDone &&
          w.visit[at(x + 1, y)] == kSpanDone && w.visit[at(x, y - 1)] == kSpanDone &&
          w.visit[at(x, y + 1)] == kSpanDone) {
        hi_sum += a;
        ++hi_n;
      }
    }
    const double hi = hi_n > 0 ? hi_sum / static_cast<double>(hi_n) : hi_max;
    if (hi - lo > 1.0) {
      const double inv_range = 1.0 / (hi - lo);
      double sw = 0.0, swx = 0.0, swy = 0.0;
      for (std::size_t k = blob_begin; k < w.in_blob.size(); ++k) {
        const std::int32_t packed = w.in_blob[k];
        const double wt = std::clamp((along(packed) - lo) * inv_range, 0.0, 1.0);
        sw += wt;
        swx += wt * unpack_x(packed);
        swy += wt * unpack_y(packed);
      }
      if (sw > 0.0) {
        u = swx / sw;
        v = swy / sw;
      }
    }
  }
  Marker m;
  m.hue = static_cast<std::uint8_t>(static_cast<int>(std::lround(hue)) & 0xff);
  m.u_px = static_cast<float>(u);
  m.v_px = static_cast<float>(v);
  m.area_px2 = static_cast<float>(area);
  out.markers.push_back(m);
  ++w.stats.accepted_per_hue[static_cast<std::size_t>(cls)];
}

Result<MarkerDetector> MarkerDetector::create(const PinholeCamera& camera, MarkerDetectorOptions options) {
  if (auto st = options.validate(); !st) return st.error();
  if (camera.width_px <= 0 || camera.height_px <= 0 || camera.width_px > 16384 || camera.height_px > 16384 ||
      !(camera.fx_px > 0.0) || !(camera.fy_px > 0.0) || !std::isfinite(camera.fx_px) || !std::isfinite(camera.fy_px)) {
    return make_error(Errc::invalid_argument,
                      "marker detector: the camera needs an image size in 1..16384 pixels and positive, finite "
                      "focal lengths (check the rig's calibration)");
  }
  auto impl = std::make_unique<Impl>();
  impl->camera = camera;
  impl->options = options;
  // A disc of diameter d at depth z on the optical axis, facing the camera.
  const double r = 0.5 * options.marker_diameter_m;
  const double a_per_z2 = kPi * r * r * camera.fx_px * camera.fy_px;
  impl->min_area = options.min_area_factor * a_per_z2 / (options.max_depth_m * options.max_depth_m);
  impl->max_area = options.max_area_factor * a_per_z2 / (options.min_depth_m * options.min_depth_m);
  for (const HueThreshold& t : options.hues) {
    impl->min_saturation_any = std::min(impl->min_saturation_any, t.min_saturation);
    impl->min_value_any = std::min(impl->min_value_any, t.min_value);
  }
  impl->inv[0] = 0.0f;
  for (std::size_t i = 1; i < impl->inv.size(); ++i) impl->inv[i] = 1.0f / static_cast<float>(i);
  impl->build_lut();
  for (Worker& w : impl->workers) impl->prepare(w);
  return MarkerDetector(std::move(impl));
}

MarkerDetector::MarkerDetector(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MarkerDetector::~MarkerDetector() = default;
MarkerDetector::MarkerDetector(MarkerDetector&&) noexcept = default;
MarkerDetector& MarkerDetector::operator=(MarkerDetector&&) noexcept = default;

Status MarkerDetector::detect(const cv::Mat& bgr, MarkerObservations& out) {
  return impl_->run(impl_->workers[0], bgr, out, "single");
}

Status MarkerDetector::detect_stereo(const cv::Mat& left_bgr, const cv::Mat& right_bgr, MarkerObservations& out_left,
                                     MarkerObservations& out_right) {
  Impl& s = *impl_;
  out_left.camera_id = 0;
  out_right.camera_id = 1;
  if (!s.options.parallel_stereo) {
    Status left = s.run(s.workers[0], left_bgr, out_left, "left");
    Status right = s.run(s.workers[1], right_bgr, out_right, "right");
    return !left ? left : right;
  }
  if (!s.helper.joinable()) {
    // Started on first use, so detectors that only see single images keep no thread.
    s.helper = std::thread([&s] {
      for (;;) {
        s.start.acquire();
        if (s.quit.load(std::memory_order_relaxed)) return;
        s.job_status = s.run(s.workers[1], *s.job_image, *s.job_out, "right");
        s.done.release();
      }
    });
  }
  s.job_image = &right_bgr;
  s.job_out = &out_right;
  s.start.release();
  Status left = s.run(s.workers[0], left_bgr, out_left, "left");
  s.done.acquire();  // the helper's writes (out_right, its stats, job_status) are visible after this
  if (!left) return left;
  return s.job_status;
}

const MarkerDetectionStats& MarkerDetector::last_stats(std::size_t camera) const noexcept {
  return impl_->workers[camera == 1 ? 1 : 0].stats;
}
const MarkerDetectorOptions& MarkerDetector::options() const noexcept { return impl_->options; }
const PinholeCamera& MarkerDetector::camera() const noexcept { return impl_->camera; }
double MarkerDetector::min_area_px2() const noexcept { return impl_->min_area; }
double MarkerDetector::max_area_px2() const noexcept { return impl_->max_area; }
int MarkerDetector::classify(std::uint8_t b, std::uint8_t g, std::uint8_t r) const noexcept {
  return impl_->classify(b, g, r, nullptr);
}

}  // namespace proprio::vist
