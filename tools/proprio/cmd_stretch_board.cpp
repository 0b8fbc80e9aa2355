#include "commands.hpp"
namespace proprio::cli {
void add_stretch_board_command(CLI::App&, int&) {}
}
