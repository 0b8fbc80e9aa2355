// proprio psychometric fit, proprio stats ..., proprio study ... (proprio::study).
#include "commands.hpp"

namespace proprio::cli {

void add_study_commands(CLI::App& app, int& exit_code) {
  (void)app;
  (void)exit_code;
}

}  // namespace proprio::cli
