// rcbench run: expand an experiment into cells, simulate each, store each in SQLite; resumable.
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>

#include "core/base/error.h"
#include "core/base/output_file.h"
#include "accel/registry.h"
#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "runner/experiment.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "cli/table.h"

namespace rcb {
namespace {

using Clock = std::chrono::steady_clock;

std::string duration_text(double seconds) {
    const int s = int(seconds + 0.5);
    char buf[32];
    if (s >= 3600)
        std::snprintf(buf, sizeof buf, "%dh%02dm", s / 3600, (s / 60) % 60);
    else
        std::snprintf(buf, sizeof buf, "%dm%02ds", s / 60, s % 60);
    return buf;
}

/// Progress: one rewritten line on stderr on a terminal, cleared when the run ends or fails; one
/// line per cell on stdout otherwise (CI logs), so that stderr holds nothing but an error's one line.
class Progress {
public:
    explicit Progress(std::size_t total) : total_(total), tty_(isatty(STDERR_FILENO)), start_(Clock::now()) {}
    ~Progress() {
        if (tty_) std::cerr << "\r\033[K" << std::flush;
    }
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;
    /// `total` grows when rounds of repetitions are added where the stored ones disagree.
    void cell(std::size_t done, std::size_t total, const std::string& what) {
        total_ = total;
        const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
        const double eta = done ? elapsed / double(done) * double(total_ - done) : 0.0;
        std::string line = "cell " + std::to_string(done + 1) + "/" + std::to_string(total_) + "  " + what +
                           "  elapsed " + duration_text(elapsed) + (done ? "  eta " + duration_text(eta) : "");
        if (tty_)
            std::cerr << "\r\033[K" << line << std::flush;
        else
            std::cout << line << std::endl;
    }

private:
    std::size_t total_;
    bool tty_;
    Clock::time_point start_;
};

/// "K/N" → (K, N) with 1 <= K <= N <= kMaxPlanCells, decimal digits only.
std::pair<std::size_t, std::size_t> parse_shard(const std::string& text) {
    std::size_t k = 0, n = 0;
    const char* end = text.data() + text.size();
    auto [after_k, ek] = std::from_chars(text.data(), end, k);
    bool ok = ek == std::errc() && after_k != end && *after_k == '/';
    if (ok) {
        auto [after_n, en] = std::from_chars(after_k + 1, end, n);
        ok = en == std::errc() && after_n == end && k >= 1 && k <= n && n <= kMaxPlanCells;
    }
    if (!ok)
        throw InputError("--shard " + text + ": expected K/N with 1 <= K <= N <= " + std::to_string(kMaxPlanCells) +
                         ", e.g. 2/8");
    return {k, n};
}

/// The thesis' layout from this run: configurations × scenes, the median over repetitions of the
/// ray cast ms with the half-width of its 95% interval between repetitions, and update ms.
void print_summary(Database& db, std::int64_t run_id, const Experiment& e) {
    struct Cellsum {
        RepetitionInterval cast, update;
        std::int64_t mismatches = 0;
        std::size_t slow = 0;
    };
    std::map<std::pair<std::string, std::string>, Cellsum> by;  // (config label, scene) → values
    for (const CellInterval& row : cell_intervals(db, run_id)) {
        Cellsum& c = by[{config_label({row.structure, row.params}), row.scene}];
        c.cast = row.raycast;
        c.update = row.update;
    }
    for (const CellSummary& row : cell_summaries(db, run_id)) {
        Cellsum& c = by[{config_label({row.structure, row.params}), row.scene}];
        c.mismatches += row.mismatches;
        c.slow += row.slow;
    }
    std::vector<std::string> scenes, labels;
    for (const SceneSpec& sc : e.scenes)
        if (std::find(scenes.begin(), scenes.end(), sc.name) == scenes.end()) scenes.push_back(sc.name);
    for (const ConfigSpec& c : e.configs) labels.push_back(config_label(c));
    std::vector<std::string> header{"ray cast ms +-95% (update ms)"};
    header.insert(header.end(), scenes.begin(), scenes.end());
    TextTable t(header);
    std::int64_t mismatches = 0;
    std::size_t slow = 0;
    for (const std::string& label : labels) {
        std::vector<std::string> row{label};
        for (const std::string& scene : scenes) {
            auto it = by.find({label, scene});
            if (it == by.end() || it->second.cast.repetitions == 0) {
                row.push_back("-");
                continue;
            }
            const RepetitionInterval& c = it->second.cast;
            const std::string interval = c.has_interval() && std::isfinite(c.relative_half_width())
                                             ? " +-" + fixed(100 * c.relative_half_width(), 1) + "%"
                                             : "";
            row.push_back(fixed(c.median / 1e6, 3) + interval + " (" + fixed(it->second.update.median / 1e6, 4) + ")" +
                          (it->second.slow ? " *" : ""));
            mismatches += it->second.mismatches;
            slow += it->second.slow;
        }
        t.add(row);
    }
    std::cout << "run " << run_id << " of experiment " << e.name
              << " (medians over frames, then over repetitions; +-: half-width of the 95% interval between the "
              << e.repetitions << " planned repetitions, as a share of the median; cell_interval)\n";
    t.print(std::cout);
    if (slow)
        std::cout << "* " << slow
                  << " cells measured while the machine was slow (calibration loop or memory probe more than 10% above "
                     "the run's "
                     "median; cell_state.slow)\n";
    if (mismatches) std::cout << "MISMATCHES against the ground truth: " << mismatches << '\n';
}

}  // namespace

void add_run_command(CLI::App& app) {
    struct Options {
        std::string experiment;
        std::string db = "results/rcbench.db";
        std::string shard;
        bool new_run = false;
        std::int64_t run_id = 0;
        bool dry_run = false;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd =
        app.add_subcommand("run",
                           "Run an experiment file into a SQLite results database, or resume an unfinished run\n"
                           "Run an experiment file (structures x scenes x parameters x repetitions) into a "
                           "SQLite database; running it again resumes an unfinished run");
    cmd->add_option("experiment", o->experiment, "Experiment file (JSON; see experiments/README.md)")
        ->required()
        ->check(input_file());
    cmd->add_option("--db", o->db, "Results database (created if missing)")->capture_default_str();
    cmd->add_option("--shard", o->shard,
                    "Run only every N-th cell, starting at the K-th: K/N (merge shards with rcbench merge)");
    cmd->add_flag("--new-run", o->new_run, "Start a new run even if an unfinished one could be resumed");
    cmd->add_option("--run", o->run_id, "Resume this run id")->check(run_id());
    cmd->add_flag("--dry-run", o->dry_run, "Print the plan and stop");
    cmd->callback([o] {
        const Experiment e = load_experiment(o->experiment);
        say_deprecated_keys(o->experiment, e.scenes);
        if (!o->dry_run) {
            std::vector<std::string> inputs{o->experiment};
            for (const SceneSpec& scene : e.scenes) inputs.push_back(scene.path);
            check_output_path(o->db, inputs, "--db");
        }
        std::size_t shard_k = 1, shard_n = 1;
        if (!o->shard.empty()) std::tie(shard_k, shard_n) = parse_shard(o->shard);
        const std::vector<Cell> plan = shard_plan(e, shard_k, shard_n);
        if (o->dry_run) {
            std::cout << e.name << ": " << e.scenes.size() << " scenes x " << e.configs.size() << " configurations x "
                      << e.repetitions << " repetitions = " << e.plan.size() << " cells"
                      << (o->shard.empty() ? "" : ", " + std::to_string(plan.size()) + " in shard " + o->shard) << '\n';
            for (const Cell& c : plan)
                std::cout << "  " << c.key << "  " << e.scenes[c.scene].name << "  "
                          << config_label(e.configs[c.config]) << "  rep " << c.repetition << '\n';
            return;
        }

        RunOptions run;
        run.db = o->db;
        run.shard_k = shard_k, run.shard_n = shard_n;
        run.new_run = o->new_run;
        run.run_id = o->run_id;
        run.on_wait = [&] {
            std::cout << "another rcbench run is writing " << o->db << "; waiting for it to finish" << std::endl;
        };
        std::unique_ptr<Progress> progress;
        const RunOutcome done =
            run_experiment(e, o->experiment, run, [&](std::size_t ran, std::size_t todo, const std::string& what) {
                if (!progress) progress = std::make_unique<Progress>(todo);
                progress->cell(ran, todo, what);
            });
        progress.reset();
        std::cout << "run " << done.run << " of " << e.name << ": " << done.planned << " cells, " << done.done_before
                  << " done before, " << done.ran << " ran now -> " << o->db << '\n';
        if (done.added)
            std::cout << done.added
                      << " repetitions added where the 95% interval of a cell's median over its repetitions was "
                         "wider than +-"
                      << fixed(100 * e.repeat_interval, 1) << "% of it (at most " << e.max_repetitions
                      << " per cell); they count in the median, the interval rests on the " << e.repetitions
                      << " planned\n";
        if (done.resampled)
            std::cout << done.resampled << " cells waited for a slow machine before they were measured\n";
        if (done.calibrations > 1)
            std::cout << "calibrated every structure " << done.calibrations << " times, at least "
                      << run.calibration_spacing.count() << " s apart; the fit reads each micro-scene's fastest pass\n";
        print_summary(*open_read_only(o->db), done.run, e);
        if (done.mismatches)
            throw std::runtime_error(std::to_string(done.mismatches) +
                                     " hits disagree with the ground truth (see the cell table)");
    });
}

}  // namespace rcb
