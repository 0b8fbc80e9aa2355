// proprio array layout|check: stretch sensor array layouts (issue 30,
// docs/stretch-arrays.md). `layout` writes a shipped example as a TOML file to
// start from; `check` reads one and says whether its cells can be read out,
// with the rank and condition number of the measurement plan.
#include <cstdio>
#include <memory>
#include <string>

#include "commands.hpp"
#include "proprio/core/file_io.hpp"
#include "proprio/stretch_array/array_layout.hpp"

namespace proprio::cli {

namespace {

using stretch_array::StripArrayLayout;

struct LayoutArgs {
  std::string example = "prototype-92";
  std::string out;
  bool force = false;
};

StripArrayLayout example_layout(const std::string& name) {
  if (name == "biceps-144") return StripArrayLayout::biceps_144();
  if (name == "fig-4-6") return StripArrayLayout::grid("fig_4_6", 2, 3, 0.02, 0.015);
  return StripArrayLayout::prototype_92();
}

int run_layout(const LayoutArgs& a) {
  const std::string text = example_layout(a.example).to_toml();
  if (a.out.empty()) {
    std::fputs(text.c_str(), stdout);
    return 0;
  }
  if (auto s = write_file_atomic(a.out, text, "stretch array layout", a.force); !s) return report_error(s.error());
  std::printf("wrote %s (%s)\n", a.out.c_str(), a.example.c_str());
  return 0;
}

int run_check(const std::string& file) {
  auto layout = StripArrayLayout::load(file);
  if (!layout) return report_error(layout.error());
  const stretch_array::LayoutCheck r = stretch_array::check_layout(*layout);
  std::printf("%s: %zu top + %zu bottom strips\n%s\n", layout->name.empty() ? file.c_str() : layout->name.c_str(),
              layout->top_strips.size(), layout->bottom_strips.size(), r.describe().c_str());
  if (r.rank_m1 < static_cast<long>(r.cells)) {
    std::printf("M^I alone (strip pairs) cannot read every cell: the single-strip rows (M^II) are needed.\n");
  }
  if (auto s = stretch_array::require_readable(*layout); !s) return report_error(s.error());
  return 0;
}

}  // namespace

void add_array_commands(CLI::App& app, int& exit_code) {
  CLI::App* group = add_command(app, "array");
  auto layout_args = std::make_shared<LayoutArgs>();
  CLI::App* layout = group->add_subcommand(
      "layout", "Write a shipped stretch sensor array layout as TOML, to start your own from (stdout without --out)");
  layout->add_option("--example", layout_args->example,
                     "prototype-92 (12 + 12 strips, 92 cells), biceps-144 (12 + 12, 144 cells) or fig-4-6 (the "
                     "thesis's 2 x 3 read-out example)")
      ->check(CLI::IsMember({"prototype-92", "biceps-144", "fig-4-6"}))
      ->capture_default_str();
  layout->add_option("--out", layout_args->out, "The TOML file to write");
  layout->add_flag("--force", layout_args->force, "Overwrite an existing file");
  layout->callback([layout_args, &exit_code] { exit_code = run_layout(*layout_args); });

  auto file = std::make_shared<std::string>();
  CLI::App* check = group->add_subcommand(
      "check", "Read a layout and say whether its cells can be read out: rank and condition number of the "
               "measurement plan (strip pairs M^I, then with the single strips M^II). Exit 1 if it cannot be read.");
  check->add_option("layout", *file, "The layout TOML file")->required();
  check->callback([file, &exit_code] { exit_code = run_check(*file); });
}

}  // namespace proprio::cli
