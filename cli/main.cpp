// rcbench: find, tune and explain the best acceleration structure for ray casting in dynamic scenes.
#include <iostream>
#include <string>
#include <string_view>

#include "cli/commands.h"
#include "core/base/error.h"

namespace {

/// An error as one line: a message may quote user text holding newlines or other control bytes.
std::string one_line(std::string_view message) {
    std::string out;
    for (unsigned char c : message) {
        if (c == '\n')
            out += "\\n";
        else if (c == '\r')
            out += "\\r";
        else if (c == '\t')
            out += "\\t";
        else if (c < 0x20 || c == 0x7f)
            out += "?";
        else
            out += char(c);
    }
    return out;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{
        "rcbench: acceleration structures for ray casting (all, closest and any hit) in dynamic physics scenes.\n"
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
    rcb::add_validate_command(app);
    rcb::add_report_command(app);
    rcb::add_findings_command(app);
    rcb::add_tune_command(app);
    rcb::add_advise_command(app);
    rcb::add_categories_command(app);
    rcb::add_archive_command(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::RequiredError& e) {
        // "A subcommand is required" when the first word is not one: name that word.
        if (argc > 1 && app.get_subcommands().empty())
            std::cerr << "rcbench: " << one_line(argv[1]) << ": not a subcommand (see rcbench --help)\n";
        else
            std::cerr << "rcbench: " << one_line(e.what()) << " (see rcbench --help)\n";
        return 2;
    } catch (const CLI::ParseError& e) {
        std::cerr << "rcbench: " << one_line(e.what()) << " (see rcbench --help)\n";
        return 2;
    } catch (const rcb::InputError& e) {
        std::cerr << "rcbench: " << one_line(e.what()) << '\n';
        return 2;
    } catch (const std::exception& e) {
        std::cerr << "rcbench: error: " << one_line(e.what()) << '\n';
        return 1;
    }
    return 0;
}
