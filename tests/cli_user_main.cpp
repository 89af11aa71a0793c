// A program outside rcbench as its README tells one to write it: its own structure registered, then
// the whole command line (rcbench::cli, cli/cli.h). tests/cli_test.cpp runs it beside the rcbench
// executable: the same one-line errors, its structure in experiments, its runs under its own name.
#include "cli/cli.h"
#include "accel/registry.h"
#include "tests/test_support.h"

int main(int argc, char** argv) {
    rcb::register_structure<rcb::test::ToyList>("toy_list", "a list scanned in blocks (tests/cli_user_main.cpp)");
    return rcb::cli::main(argc, argv);
}
