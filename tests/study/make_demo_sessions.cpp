// Writes a small demo study for the CLI tests and the docs: every participant
// of a design answered by a simulated 2AFC Weibull observer whose threshold
// depends on the first factor's level (level i: alpha = 6 / (1 + i/2)).
// Not the thesis's simulated participant (that is the sample's): just enough
// data with known thresholds to exercise `proprio study analyze`.
//   study_demo_sessions DESIGN.toml OUT_DIR [PARTICIPANTS] [SEED]
#include <cstdio>
#include <cstdlib>
#include <string>

#include "proprio/study/session.hpp"
#include "simulated_observer.hpp"

int main(int argc, char** argv) {
  using namespace proprio::study;
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s DESIGN.toml OUT_DIR [PARTICIPANTS] [SEED]\n", argv[0]);
    return 2;
  }
  const int participants = argc > 3 ? std::atoi(argv[3]) : 4;
  const std::uint64_t seed = argc > 4 ? std::strtoull(argv[4], nullptr, 10) : 1;
  auto design = StudyDesign::load_file(argv[1]);
  if (!design) {
    std::fprintf(stderr, "error: %s\n", design.error().message.c_str());
    return 1;
  }
  for (int p = 0; p < participants; ++p) {
    SessionOptions o;
    o.out_dir = argv[2];
    o.participant = "P" + std::to_string(p + 1);
    o.participant_index = p;
    o.sync_each_trial = false;  // simulated observers: nothing to lose in a crash
    o.device_json = R"j({"observer": "tests/study/make_demo_sessions.cpp (simulated 2AFC Weibull)"})j";
    auto s = Session::open(*design, o);
    if (!s) {
      std::fprintf(stderr, "error: %s\n", s.error().message.c_str());
      return 1;
    }
    while (!s->finished()) {
      auto t = s->next_trial();
      if (!t) return 1;
      int level_index = 0;
      if (!design->factors.empty()) {
        const auto& levels = design->factors[0].levels;
        for (std::size_t i = 0; i < levels.size(); ++i) {
          if (levels[i] == t->levels[0]) level_index = static_cast<int>(i);
        }
      }
      testing::SimulatedObserver obs;
      obs.params = {6.0 / (1.0 + level_index / 2.0), 3.0, 0.5, 0.01};
      obs.seed = proprio::mix_seed(seed, static_cast<std::uint64_t>(p));
      Response r;
      r.correct = obs.respond(t->stimulus, static_cast<std::uint64_t>(t->index));
      if (auto st = s->record(*t, r); !st) {
        std::fprintf(stderr, "error: %s\n", st.error().message.c_str());
        return 1;
      }
    }
    std::printf("%s: %d trials\n", s->csv_path().c_str(), s->completed_trials());
  }
  return 0;
}
