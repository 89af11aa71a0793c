// rcbench: find, tune and explain the best acceleration structure for ray casting in dynamic scenes.
#include <iostream>

#include "cli/commands.h"
#include "core/error.h"

int main(int argc, char** argv) {
    CLI::App app{"rcbench: acceleration structures for all-hits ray casting in dynamic physics scenes.\n"
                 "Generate or import scenes, simulate structures against brute-force ground truth, run experiment files\n"
                 "into a SQLite database, compare runs, cast your own rays.",
                 "rcbench"};
    app.set_version_flag("--version", std::string("rcbench 0.1.0"));
    app.require_subcommand(1);
    app.fallthrough();
    rcb::add_scene_commands(app);
    rcb::add_simulate_command(app);
    rcb::add_cast_command(app);
    rcb::add_structures_command(app);
    rcb::add_run_command(app);
    rcb::add_query_commands(app);
    rcb::add_history_command(app);
    rcb::add_fit_command(app);
    rcb::add_report_command(app);
    rcb::add_tune_command(app);
    rcb::add_advise_command(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::cerr << "rcbench: " << e.what() << " (see rcbench --help)\n";
        return 2;
    } catch (const rcb::InputError& e) {
        std::cerr << "rcbench: " << e.what() << '\n';
        return 2;
    } catch (const std::exception& e) {
        std::cerr << "rcbench: error: " << e.what() << '\n';
        return 1;
    }
    return 0;
}
