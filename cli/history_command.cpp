// rcbench history: per scene and configuration, the median frame time of every run in run order,
// and the steps where the level changed beyond the runs' noise (runner/history.h says how).
#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <set>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/table.h"
#include "core/base/error.h"
#include "core/base/number_text.h"
#include "runner/history.h"
#include "runner/store.h"

namespace rcb {
namespace {

std::string p_text(double p) { return p < 1e-4 ? "p<0.0001" : "p=" + fixed(p, 4); }

/// "step at run 7 (abc1234): +12.3%, p=0.001" for every step of the series, or "none".
std::string steps_text(const HistorySeries& s) {
    std::string out;
    for (const Step& step : s.steps) {
        const HistoryPoint& p = s.points[step.at];
        out += (out.empty() ? "" : "; ") + std::string("step at run ") + std::to_string(p.run) + " (" +
               short_commit(p.commit) + "): " +
               (std::isfinite(step.change) ? (step.change >= 0 ? "+" : "") + fixed(100 * step.change, 1) + "%"
                                           : "from 0") +
               ", " + p_text(step.p_value);
        if (s.points[step.at - 1].scene_hash != p.scene_hash) out += " (scene content changed)";
    }
    return out.empty() ? "none" : out;
}

struct HistoryOptions {
    std::string db;
    HistoryQuery query;
    std::size_t last = 0;
};

void print_history(const HistoryOptions& o) {
    auto db = open_read_only(o.db);
    const std::vector<HistorySeries> series = load_history(*db, o.query);
    // Columns: every run any series has, in run order (series list their points in that order).
    std::vector<std::pair<std::int64_t, std::string>> runs;  // (id, started_at)
    std::set<std::int64_t> seen;
    std::set<std::string> experiments, binaries;
    for (const HistorySeries& s : series) {
        experiments.insert(s.experiment);
        binaries.insert(s.binary);
        for (const HistoryPoint& p : s.points)
            if (seen.insert(p.run).second) runs.emplace_back(p.run, p.started_at);
    }
    std::stable_sort(runs.begin(), runs.end(), [](const auto& a, const auto& b) {
        return a.second != b.second ? a.second < b.second : a.first < b.first;
    });
    const std::size_t first = o.last > 0 && runs.size() > o.last ? runs.size() - o.last : 0;
    const bool several = experiments.size() > 1;
    // The runs of each program are series of their own (runner/history.h): named when there are several.
    const bool programs = binaries.size() > 1;

    std::vector<std::string> header;
    if (several) header.push_back("experiment");
    if (programs) header.push_back("binary");
    header.insert(header.end(), {"scene", "structure", "params"});
    for (std::size_t r = first; r < runs.size(); ++r) header.push_back("run " + std::to_string(runs[r].first));
    header.push_back("steps");
    TextTable t(header);
    std::size_t steps = 0;
    for (const HistorySeries& s : series) {
        std::vector<std::string> row;
        if (several) row.push_back(s.experiment);
        if (programs) row.push_back(s.binary);
        row.insert(row.end(), {s.scene, s.structure, s.params});
        for (std::size_t r = first; r < runs.size(); ++r) {
            std::string cell = "-";
            for (const HistoryPoint& p : s.points)
                if (p.run == runs[r].first) cell = format_ms(p.median_ns / 1e6) + " (" + short_commit(p.commit) + ")";
            row.push_back(cell);
        }
        row.push_back(steps_text(s));
        steps += s.steps.size();
        t.add(std::move(row));
    }
    std::cout << (o.query.metric == "raycast" ? "Ray cast" : "Update")
              << " per frame, median over frames (ms), per run in run order"
              << (first > 0 ? " (last " + std::to_string(runs.size() - first) + " of " + std::to_string(runs.size()) +
                                  " runs shown)"
                            : "")
              << ". A step: a median shift beyond " << fixed(o.query.steps.k, 1)
              << " MADs of the frame times and Mann-Whitney U p < " << o.query.steps.alpha << " between up to "
              << o.query.steps.window << " runs before and after it.\n";
    t.print(std::cout);
    std::cout << steps << " steps in " << series.size() << " series over " << runs.size() << " runs.\n";
}

}  // namespace

void add_history_command(CLI::App& app) {
    auto o = std::make_shared<HistoryOptions>();
    CLI::App* history =
        app.add_subcommand("history",
                           "Every run's median frame time per scene and configuration, and the steps between runs\n"
                           "Per scene and configuration, the median frame time of every run in run "
                           "order, and the steps beyond the runs' noise");
    history->add_option("db", o->db, "Results database")->required()->check(input_file());
    history->add_option("--experiment", o->query.experiment, "Only this experiment (default: every experiment)")
        ->check(non_empty());
    history->add_option("--scene", o->query.scene, "Only this scene (its name in the experiment)")->check(non_empty());
    history->add_option("--structure", o->query.structure, "Only this structure (e.g. dbvh)")->check(non_empty());
    history
        ->add_option("--binary", o->query.binary,
                     "Only the runs of this program (run.binary: rcbench, or a program linking rcbench::cli)")
        ->check(non_empty());
    history->add_option("--metric", o->query.metric, "raycast or update")
        ->capture_default_str()
        ->check(CLI::IsMember({"raycast", "update"}));
    history->add_option("--threshold", o->query.steps.k, "A step must exceed this many MADs of the frame times")
        ->capture_default_str()
        ->check(finite_range(0, 1e6));
    history->add_option("--alpha", o->query.steps.alpha, "Significance level of the Mann-Whitney U test")
        ->capture_default_str()
        ->check(finite_range(1e-12, 0.5));
    history->add_option("--window", o->query.steps.window, "Runs compared on either side of a boundary")
        ->capture_default_str()
        ->check(whole_number(1, 1'000'000));
    history->add_option("--last", o->last, "Show only the last N runs' columns (steps use every run)")
        ->check(whole_number(1, 1'000'000));
    history->callback([o] { print_history(*o); });
}

}  // namespace rcb
