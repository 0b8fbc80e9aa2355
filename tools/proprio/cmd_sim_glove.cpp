#include "commands.hpp"
namespace proprio::cli {
void add_sim_glove_command(CLI::App&, int&) {}
}
