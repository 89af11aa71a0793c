// rcb::cli::main (cli/cli.h): the rcbench command line, for the rcbench executable and for a
// program that registers its own structures first.
#include "cli/cli.h"

#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <string_view>

#include "cli/commands.h"
#include "core/base/error.h"

namespace rcb {
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

/// `rcbench --help` lists each subcommand on one line, its description's first line: a newcomer scans
/// the list; the subcommand's own --help prints the whole description. CLI11 (App.hpp, App's constructor)
/// gives every subcommand its parent's formatter when it is added, so one set on the top app after
/// the subcommands changes this list alone.
class SummaryFormatter : public CLI::Formatter {
public:
    std::string make_subcommand(const CLI::App* sub) const override {
        const std::string& description = sub->get_description();
        std::ostringstream out;
        CLI::detail::format_help(out, sub->get_display_name(true), description.substr(0, description.find('\n')),
                                 column_width_);
        return out.str();
    }
};

}  // namespace

namespace cli {

int main(int argc, char** argv) {
    CLI::App app{
        "rcbench: acceleration structures for ray casting (all, closest and any hit) in dynamic physics\n"
        "scenes. Generate or import scenes, simulate structures against brute-force ground truth, run\n"
        "experiment files into a SQLite database, compare runs, cast your own rays.\n"
        "Each subcommand's --help tells its options and what it does in full.",
        "rcbench"};
    app.set_version_flag("--version", std::string("rcbench 0.1.0"));
    app.require_subcommand(1);
    app.fallthrough();
    add_scene_commands(app);
    add_simulate_command(app);
    add_cast_command(app);
    add_structures_command(app);
    add_run_command(app);
    add_query_commands(app);
    add_history_command(app);
    add_fit_command(app);
    add_validate_command(app);
    add_report_command(app);
    add_findings_command(app);
    add_tune_command(app);
    add_advise_command(app);
    add_categories_command(app);
    add_archive_command(app);
    auto summaries = std::make_shared<SummaryFormatter>();
    summaries->column_width(14);  // the longest name, "categories", and its indent fit
    app.formatter(summaries);
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

}  // namespace cli
}  // namespace rcb
