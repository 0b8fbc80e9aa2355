#pragma once
// A terminal progress bar on stderr for work that takes longer than a second.
// It stays silent for short work and when stderr is not a terminal (CI logs
// get one summary line instead of hundreds of redraws).
#include <chrono>
#include <string>

namespace proprio::cli {

class ProgressBar {
 public:
  ProgressBar(std::string label, double total, std::string unit);
  ~ProgressBar();
  void update(double done);
  void finish();

 private:
  void draw(double done, bool final_line);
  std::string label_, unit_;
  double total_;
  std::chrono::steady_clock::time_point start_, last_draw_;
  bool tty_, shown_ = false, finished_ = false;
};

}  // namespace proprio::cli
