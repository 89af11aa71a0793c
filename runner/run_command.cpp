// rcbench run: expand an experiment into cells, simulate each, store each in SQLite; resumable.
#include <unistd.h>

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>

#include "core/error.h"
#include "core/registry.h"
#include "runner/commands.h"
#include "runner/experiment.h"
#include "runner/store.h"
#include "runner/table.h"

namespace rcb {
namespace {

using Clock = std::chrono::steady_clock;

std::string duration_text(double seconds) {
    const int s = int(seconds + 0.5);
    char buf[32];
    if (s >= 3600) std::snprintf(buf, sizeof buf, "%dh%02dm", s / 3600, (s / 60) % 60);
    else std::snprintf(buf, sizeof buf, "%dm%02ds", s / 60, s % 60);
    return buf;
}

/// Progress on stderr: one rewritten line on a terminal, one line per cell otherwise (CI logs).
class Progress {
public:
    explicit Progress(std::size_t total) : total_(total), tty_(isatty(STDERR_FILENO)), start_(Clock::now()) {}
    void cell(std::size_t done, const std::string& what) {
        const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
        const double eta = done ? elapsed / double(done) * double(total_ - done) : 0.0;
        std::string line = "cell " + std::to_string(done + 1) + "/" + std::to_string(total_) + "  " + what + "  elapsed " +
                           duration_text(elapsed) + (done ? "  eta " + duration_text(eta) : "");
        if (tty_) std::cerr << "\r\033[K" << line << std::flush;
        else std::cerr << line << '\n';
    }
    void finish() {
        if (tty_) std::cerr << "\r\033[K";
    }

private:
    std::size_t total_;
    bool tty_;
    Clock::time_point start_;
};

/// "K/N" → (K, N) with 1 <= K <= N.
std::pair<std::size_t, std::size_t> parse_shard(const std::string& text) {
    std::size_t k = 0, n = 0;
    char slash = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%zu%c%zu%c", &k, &slash, &n, &extra) != 3 || slash != '/' || k < 1 || k > n)
        throw InputError("--shard " + text + ": expected K/N with 1 <= K <= N, e.g. 2/8");
    return {k, n};
}

/// Short label of a configuration: its structure and the parameters that differ from the defaults.
std::string config_label(const ConfigSpec& c) {
    const nlohmann::json defaults = find_structure(c.structure).defaults();
    std::string label = c.structure;
    std::string changed;
    for (const auto& [k, v] : c.params.items())
        if (!defaults.contains(k) || defaults[k] != v) changed += (changed.empty() ? "" : ",") + k + "=" + v.dump();
    return changed.empty() ? label : label + " " + changed;
}

/// The thesis' layout from this run: configurations × scenes, median ray cast ms (update ms).
void print_summary(Database& db, std::int64_t run_id, const Experiment& e) {
    struct Cellsum {
        std::vector<double> cast, update;
        std::int64_t mismatches = 0;
    };
    std::map<std::pair<std::string, std::string>, Cellsum> by;  // (config label, scene) → values
    Statement s = db.prepare(
        "SELECT scene.name, config.structure, config.params, cell.raycast_ns_median, cell.update_ns_median, cell.mismatches "
        "FROM cell JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id WHERE cell.run_id = ?");
    s.bind(1, run_id);
    while (s.step()) {
        const std::string label = config_label({s.text(1), nlohmann::json::parse(s.text(2))});
        Cellsum& c = by[{label, s.text(0)}];
        c.cast.push_back(s.real(3));
        c.update.push_back(s.real(4));
        c.mismatches += s.int64(5);
    }
    std::vector<std::string> scenes, labels;
    for (const SceneSpec& sc : e.scenes)
        if (std::find(scenes.begin(), scenes.end(), sc.name) == scenes.end()) scenes.push_back(sc.name);
    for (const ConfigSpec& c : e.configs) labels.push_back(config_label(c));
    std::vector<std::string> header{"ray cast ms (update ms)"};
    header.insert(header.end(), scenes.begin(), scenes.end());
    TextTable t(header);
    std::int64_t mismatches = 0;
    for (const std::string& label : labels) {
        std::vector<std::string> row{label};
        for (const std::string& scene : scenes) {
            auto it = by.find({label, scene});
            if (it == by.end()) {
                row.push_back("-");
                continue;
            }
            const Spread c = spread_of(it->second.cast), u = spread_of(it->second.update);
            row.push_back(fixed(c.median / 1e6, 3) + " (" + fixed(u.median / 1e6, 4) + ")");
            mismatches += it->second.mismatches;
        }
        t.add(row);
    }
    std::cout << "run " << run_id << " of experiment " << e.name << " (medians over frames and repetitions)\n";
    t.print(std::cout);
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
    CLI::App* cmd = app.add_subcommand("run", "Run an experiment file (structures x scenes x parameters x repetitions) into a "
                                              "SQLite database; running it again resumes an unfinished run");
    cmd->add_option("experiment", o->experiment, "Experiment file (JSON; see experiments/README.md)")->required();
    cmd->add_option("--db", o->db, "Results database (created if missing)")->capture_default_str();
    cmd->add_option("--shard", o->shard, "Run only every N-th cell, starting at the K-th: K/N (merge shards with rcbench merge)");
    cmd->add_flag("--new-run", o->new_run, "Start a new run even if an unfinished one could be resumed");
    cmd->add_option("--run", o->run_id, "Resume this run id");
    cmd->add_flag("--dry-run", o->dry_run, "Print the plan and stop");
    cmd->callback([o] {
        const Experiment e = load_experiment(o->experiment);
        std::size_t shard_k = 1, shard_n = 1;
        if (!o->shard.empty()) std::tie(shard_k, shard_n) = parse_shard(o->shard);
        std::vector<Cell> plan;
        for (std::size_t i = 0; i < e.plan.size(); ++i)
            if (i % shard_n == shard_k - 1) plan.push_back(e.plan[i]);
        if (o->dry_run) {
            std::cout << e.name << ": " << e.scenes.size() << " scenes x " << e.configs.size() << " configurations x "
                      << e.repetitions << " repetitions = " << e.plan.size() << " cells"
                      << (o->shard.empty() ? "" : ", " + std::to_string(plan.size()) + " in shard " + o->shard) << '\n';
            for (const Cell& c : plan)
                std::cout << "  " << c.key << "  " << e.scenes[c.scene].name << "  " << config_label(e.configs[c.config])
                          << "  rep " << c.repetition << '\n';
            return;
        }

        ResultStore store(o->db);
        const std::int64_t experiment = store.experiment_id(e);
        const std::string shard = o->shard.empty() ? "" : std::to_string(shard_k) + "/" + std::to_string(shard_n);
        std::int64_t run = 0;
        if (o->run_id) {
            if (!store.run_exists(o->run_id)) throw InputError("--run " + std::to_string(o->run_id) + ": no such run in " + o->db);
            run = o->run_id;
        } else if (auto unfinished = o->new_run ? std::nullopt : store.unfinished_run(experiment, e.hash, shard)) {
            run = *unfinished;
        } else {
            run = store.begin_run(experiment, RunInfo::current(e.threads, shard, e));
        }
        const std::set<std::string> done = store.finished_cells(run);
        std::size_t todo = 0;
        for (const Cell& c : plan) todo += done.count(c.key) == 0;
        std::cerr << "run " << run << " of " << e.name << ": " << plan.size() << " cells, " << plan.size() - todo
                  << " already done, " << todo << " to run -> " << o->db << '\n';

        tbb::global_control threads(tbb::global_control::max_allowed_parallelism, e.threads);
        SimulationOptions sim;
        sim.verify = e.verify;
        sim.warmup_frames = e.warmup_frames;
        Progress progress(todo);
        std::size_t ran = 0;
        std::uint64_t mismatches = 0;
        // Cells are scene-major, so each scene is loaded once.
        std::size_t loaded = SIZE_MAX;
        Recording recording;
        std::string scene_hash;
        for (const Cell& c : plan) {
            if (done.count(c.key) || store.cell_done(run, c.key)) continue;
            const SceneSpec& scene = e.scenes[c.scene];
            const ConfigSpec& config = e.configs[c.config];
            progress.cell(ran, scene.name + "  " + config_label(config) + "  rep " + std::to_string(c.repetition));
            if (loaded != c.scene) {
                recording = load_scene(scene);
                scene_hash = recording_hash(recording);
                loaded = c.scene;
            }
            const SimulationResult res = simulate(recording, find_structure(config.structure), config.params, sim);
            mismatches += res.mismatches();
            store.store_cell(run, experiment, c, scene, recording, scene_hash, res);
            ++ran;
        }
        progress.finish();
        const std::set<std::string> now_done = store.finished_cells(run);
        if (std::all_of(plan.begin(), plan.end(), [&](const Cell& c) { return now_done.count(c.key) != 0; }))
            store.finish_run(run);
        print_summary(store.db(), run, e);
        if (mismatches) throw std::runtime_error(std::to_string(mismatches) + " hits disagree with the ground truth (see the cell table)");
    });
}

}  // namespace rcb
