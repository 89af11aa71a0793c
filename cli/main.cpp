// rcbench: find, tune and explain the best acceleration structure for ray casting in dynamic scenes.
// The command line is the library rcbench::cli (cli/cli.h), which a program with its own
// structures calls the same way.
#include "cli/cli.h"

int main(int argc, char** argv) { return rcb::cli::main(argc, argv); }
