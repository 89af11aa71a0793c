#pragma once
/// The whole rcbench command line as a library (rcbench::cli), as Google Benchmark's
/// benchmark_main and GoogleTest's gtest_main make the harness a library: a program registers its
/// own structures (accel/registry.h register_structure) and hands its arguments to
/// rcb::cli::main, and every subcommand (run, fit, tune, advise, report, compare, history, ...)
/// knows them as it knows rcbench's own. The rcbench executable is this call alone (cli/main.cpp).
///
///     int main(int argc, char** argv) {
///         rcb::register_structure<SweepList>("sweep", "objects sorted by min x, swept per ray");
///         return rcb::cli::main(argc, argv);
///     }
///
/// Returns the exit status: 0 done, 1 failure, 2 bad input with one line on stderr (the same lines
/// as the rcbench executable's). The results database records the program that wrote each run
/// (runner/binary_identity.h), so a program's runs and rcbench's stay apart in history.

namespace rcb::cli {

int main(int argc, char** argv);

}  // namespace rcb::cli
