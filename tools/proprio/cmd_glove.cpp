// placeholder: filled in by the issue-4 work
#include "commands.hpp"
namespace proprio::cli {
void add_glove_command(CLI::App&, int&) {}
}  // namespace proprio::cli
