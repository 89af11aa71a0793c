#pragma once
/// The `rcbench` subcommands, one file each in cli/. Each `add_*` registers a subcommand and its
/// options on the CLI11 app; the work runs in the subcommand's callback, which calls the stages'
/// plain entry points and prints. Errors are exceptions: InputError for bad
/// input (exit 2), anything else a failure (exit 1); main() turns them into one line.

#include <CLI/CLI.hpp>

namespace rcb {

void add_scene_commands(CLI::App& app);
void add_simulate_command(CLI::App& app);
void add_cast_command(CLI::App& app);
void add_structures_command(CLI::App& app);
void add_run_command(CLI::App& app);
void add_query_commands(CLI::App& app);
void add_history_command(CLI::App& app);
void add_fit_command(CLI::App& app);
void add_validate_command(CLI::App& app);
void add_report_command(CLI::App& app);
void add_findings_command(CLI::App& app);
void add_tune_command(CLI::App& app);
void add_advise_command(CLI::App& app);
void add_categories_command(CLI::App& app);
void add_archive_command(CLI::App& app);

}  // namespace rcb
