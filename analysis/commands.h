#pragma once
/// The analysis stage's `rcbench` subcommands: fit and report.

#include <CLI/CLI.hpp>

namespace rcb {

void add_fit_command(CLI::App& app);
void add_report_command(CLI::App& app);

}  // namespace rcb
