#pragma once
/// The tuner's `rcbench` subcommands: tune and advise.

#include <CLI/CLI.hpp>

namespace rcb {

void add_tune_command(CLI::App& app);
void add_advise_command(CLI::App& app);

}  // namespace rcb
