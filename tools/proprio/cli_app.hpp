#pragma once
// The main of every CLI program (`proprio` and the family programs in
// libexec): the same top-level options, help text, number checks and exit
// codes, with the commands of one family registered.
#include "command_table.hpp"

namespace proprio::cli {

using AddCommands = void (*)(CLI::App& app, int& exit_code);

// `self` is the family this program carries out. Family::core is the `proprio`
// dispatcher: a command of another family is handed to its program (execv,
// same argv), and --help lists every command of the table.
int run_cli(int argc, char** argv, Family self, AddCommands add_commands);

}  // namespace proprio::cli
