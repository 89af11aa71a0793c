// rcbench findings: the thesis' conclusions checked against one run or several independent runs,
// as Markdown.
#include <filesystem>
#include <iostream>
#include <memory>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/run_ref.h"
#include "analysis/cost_model.h"
#include "analysis/findings.h"
#include "core/base/output_file.h"
#include "runner/results_reader.h"
#include "runner/store.h"

namespace rcb {

namespace {

/// The experiment a run belongs to (its name), for the check that all runs are of one experiment.
std::string experiment_of(Database& db, std::int64_t run) {
    const std::optional<StoredRun> info = read_stored_run(db, run);
    return info ? info->experiment : "";
}

}  // namespace

void add_findings_command(CLI::App& app) {
    struct Options {
        std::vector<std::string> runs;
        std::string out, experiment;
        std::int64_t run = 0;
        OverRepetitions repetitions = OverRepetitions::fastest_cast;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand(
        "findings",
        "Check the thesis' conclusions on one or several runs of one experiment (Markdown)\n"
        "Check the thesis' conclusions (UG on uniform scenes, HG on irregular ones, LBVH's trade, the full-SAH DBVH, "
        "HG's memory, traversal costs, small scenes) against one run or several independent runs of one experiment, "
        "as Markdown with the figures and counters behind each verdict, their range over the runs and how many runs "
        "alone give each verdict (the traversal-cost claim needs `rcbench fit` on each run first)");
    cmd->add_option("runs", o->runs,
                    "Results database, or DB:RUN for one of its runs; several for independent runs of one experiment "
                    "(a database without :RUN gives its newest run, of --experiment if given)")
        ->required();
    cmd->add_option("-o,--output", o->out, "Markdown file to write (default: standard output)");
    cmd->add_option("--experiment", o->experiment,
                    "A database named without :RUN gives the newest run of this experiment (default: the newest run)")
        ->check(non_empty());
    cmd->add_option("--run", o->run, "This run id (one database named without :RUN only)")->check(run_id());
    add_repetitions_option(cmd, o->repetitions);
    cmd->callback([o] {
        std::vector<RunRef> refs;
        for (const std::string& text : o->runs) refs.push_back(parse_run_ref("findings", text));
        if (o->run && (refs.size() > 1 || refs.front().run))
            throw InputError("--run " + std::to_string(o->run) + ": give one database without :RUN with --run");
        if (!o->out.empty()) {
            std::vector<std::string> inputs;
            for (const RunRef& r : refs) inputs.insert(inputs.end(), {r.path, r.path + "-wal", r.path + "-shm"});
            check_output_path(o->out, inputs, "-o");
        }
        std::vector<std::unique_ptr<Database>> dbs;
        std::vector<FindingsRun> runs;
        std::string experiment;
        for (const RunRef& ref : refs) {
            dbs.push_back(naming(ref, [&] { return open_read_only(ref.path); }));
            const std::int64_t run = ref.run
                                         ? resolve_ref(*dbs.back(), ref)
                                         : naming(ref, [&] { return resolve_run(*dbs.back(), o->run, o->experiment); });
            const std::string name = experiment_of(*dbs.back(), run);
            if (!runs.empty() && name != experiment)
                throw InputError("findings " + ref.text + ": run " + std::to_string(run) + " is of experiment '" +
                                 name + "', not '" + experiment + "' as the first run: give runs of one experiment");
            for (std::size_t k = 0; k < runs.size(); ++k)
                if (runs[k].run == run && std::filesystem::equivalent(refs[k].path, ref.path))
                    throw InputError("findings " + ref.text + ": run " + std::to_string(run) +
                                     " is given twice; the runs must be independent");
            experiment = name;
            runs.push_back({dbs.back().get(), run});
        }
        const std::string md = findings_markdown(runs, o->repetitions);
        if (o->out.empty()) {
            std::cout << md;
        } else {
            write_file_atomically(o->out, md);
            std::string ids;
            for (const FindingsRun& r : runs) ids += (ids.empty() ? "" : ", ") + std::to_string(r.run);
            std::cout << "wrote " << o->out << ": run" << (runs.size() > 1 ? "s " : " ") << ids << "\n";
        }
    });
}

}  // namespace rcb
