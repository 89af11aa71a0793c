// rcbench report: the run's tables and charts as one self-contained HTML file.
#include <iostream>
#include <memory>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "analysis/cost_model.h"
#include "analysis/report.h"
#include "core/base/output_file.h"
#include "runner/store.h"

namespace rcb {

void add_report_command(CLI::App& app) {
    struct Options {
        std::string db, out = "results/report.html", experiment;
        std::int64_t run = 0;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand(
        "report", "Write a run's thesis-style tables and charts (gnuplot) as one self-contained HTML file");
    cmd->add_option("db", o->db, "Results database")->required()->check(input_file());
    cmd->add_option("-o,--output", o->out, "HTML file to write")->capture_default_str();
    cmd->add_option("--experiment", o->experiment, "Report the newest run of this experiment (default: the newest run)")
        ->check(non_empty());
    cmd->add_option("--run", o->run, "Report this run id")->check(run_id());
    cmd->callback([o] {
        check_output_path(o->out, {o->db, o->db + "-wal", o->db + "-shm"}, "-o");
        auto db = open_read_only(o->db);
        const std::int64_t run = resolve_run(*db, o->run, o->experiment);
        const ReportSummary s = write_report(*db, run, o->out);
        std::cout << "wrote " << o->out << ": run " << s.run << ", " << s.tables << " tables, " << s.charts
                  << " charts\n";
    });
}

}  // namespace rcb
