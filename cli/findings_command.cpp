// rcbench findings: the thesis' conclusions checked against one run, as Markdown.
#include <iostream>
#include <memory>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "analysis/cost_model.h"
#include "analysis/findings.h"
#include "core/base/output_file.h"
#include "runner/store.h"

namespace rcb {

void add_findings_command(CLI::App& app) {
    struct Options {
        std::string db, out, experiment;
        std::int64_t run = 0;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand(
        "findings",
        "Check the thesis' conclusions (UG on uniform scenes, HG on irregular ones, LBVH's trade, the full-SAH DBVH, "
        "HG's memory, traversal costs, small scenes) against a run, as Markdown with the figures and counters behind "
        "each verdict (the traversal-cost claim needs `rcbench fit` first)");
    cmd->add_option("db", o->db, "Results database")->required()->check(input_file());
    cmd->add_option("-o,--output", o->out, "Markdown file to write (default: standard output)");
    cmd->add_option("--experiment", o->experiment, "The newest run of this experiment (default: the newest run)")
        ->check(non_empty());
    cmd->add_option("--run", o->run, "This run id")->check(run_id());
    cmd->callback([o] {
        if (!o->out.empty()) check_output_path(o->out, {o->db, o->db + "-wal", o->db + "-shm"}, "-o");
        auto db = open_read_only(o->db);
        const std::int64_t run = resolve_run(*db, o->run, o->experiment);
        const std::string md = findings_markdown(*db, run, evaluate_findings(*db, run));
        if (o->out.empty())
            std::cout << md;
        else {
            write_file_atomically(o->out, md);
            std::cout << "wrote " << o->out << ": run " << run << "\n";
        }
    });
}

}  // namespace rcb
