// rcbench fit: the cost model of eq. 5.4 (and update costs) fitted to a run, stored back in the database.
#include <algorithm>
#include <cmath>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <optional>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/run_ref.h"
#include "analysis/cost_model.h"
#include "analysis/noise.h"
#include "analysis/query_kinds.h"
#include "analysis/validation.h"
#include "runner/store.h"
#include "cli/validation_table.h"

namespace rcb {
namespace {

/// "4.98 [4.71, 5.25]", or the value marked unsure when its interval spans zero or has none.
std::string with_interval(const Coefficient& c, bool trusted) {
    if (!trusted) return "(" + fixed(c.value, 3) + ")";
    std::string text = fixed(c.value, 3);
    if (std::isfinite(c.ci_low)) text += " [" + fixed(c.ci_low, 3) + ", " + fixed(c.ci_high, 3) + "]";
    if (c.spans_zero) text += " ~0?";
    return text;
}

void print_models(const std::vector<CandidateModel>& models, const char* what) {
    TextTable t(
        {std::string("  ") + what + " model", "terms", "held-out error", "R2", "condition", "status", "chosen"});
    for (const CandidateModel& m : models) {
        std::string terms;
        for (const std::string& s : m.problem.terms) terms += (terms.empty() ? "" : " ") + s;
        t.add({"  " + m.name, terms, percent(m.heldout_error), fixed(m.fit.r2, 3),
               std::isfinite(m.fit.condition_number) ? fixed(m.fit.condition_number, 1) : "inf", m.fit.status(),
               m.chosen ? "yes" : ""});
    }
    t.print(std::cout);
}

void print_coefficients(const CandidateModel& m, const char* unit) {
    const bool trusted = m.fit.status() == "ok";
    std::cout << "  chosen " << m.target << " model '" << m.name << "' (" << unit << ", 95% intervals"
              << (trusted ? "" : "; NOT IDENTIFIABLE: " + m.fit.status() + ", values in parentheses are not estimates")
              << "):\n";
    for (const Coefficient& c : m.fit.coefficients) {
        std::cout << "    " << c.name << " = " << with_interval(c, trusted);
        if (std::isfinite(c.prior))
            std::cout << "   calibration " << fixed(c.prior, 3) << " (x" << fixed(c.value / c.prior, 2) << ")"
                      << (c.at_bound ? " AT THE 3x BOUND: the run's frames pull it further" : "");
        std::cout << '\n';
    }
    for (const std::string& d : m.dropped) std::cout << "    dropped " << d << '\n';
    // What each term buys: the held-out error (k-fold over scene families) refitted without it.
    std::cout << "    held-out error " << percent(m.heldout_error) << " with every term; without";
    for (const TermWorth& w : term_worth(m)) {
        std::cout << ' ' << w.term << ' ' << percent(w.without);
        if (std::isfinite(w.without) && std::isfinite(m.heldout_error))
            std::cout << " (" << (w.without >= m.heldout_error ? "+" : "")
                      << fixed(100 * (w.without - m.heldout_error), 1) << " points)";
        std::cout << ';';
    }
    std::cout << '\n';
}

/// The calibration pass's coefficients (micro-scenes, runner/calibration.h) and whether they are pinned.
void print_calibration(const StructureModels& s) {
    if (!s.calibration) {
        std::cout << "  no calibration stored with the run (made before calibration existed): no priors\n";
        return;
    }
    const std::vector<CalibrationPoint>& points = s.calibration->points;
    const int passes = points.empty() ? 0 : points.front().passes;
    std::cout << "  calibration on " << points.size() << " micro-scenes"
              << (passes > 1 ? ", each its fastest of " + std::to_string(passes) + " passes" : std::string())
              << " (condition " << fixed(s.calibration->condition_number, 1) << "):";
    for (const CalibratedTerm& t : s.calibration->terms) {
        std::cout << "  " << t.name << " = " << fixed(t.value, 3);
        if (std::isfinite(t.ci_low)) std::cout << " [" << fixed(t.ci_low, 3) << ", " << fixed(t.ci_high, 3) << "]";
        if (!t.pinned) std::cout << " (not pinned: " << t.why << ")";
    }
    std::cout << '\n';
}

/// One row per structure, one column per scene: `cell(structure, scene)`.
void print_scene_table(const std::vector<StructureModels>& models, const std::vector<std::string>& scenes,
                       const std::function<std::string(const StructureModels&, const std::string&)>& cell) {
    std::vector<std::string> header{"structure"};
    header.insert(header.end(), scenes.begin(), scenes.end());
    TextTable l(header);
    for (const StructureModels& s : models) {
        std::vector<std::string> row{s.structure};
        for (const std::string& scene : scenes) row.push_back(cell(s, scene));
        l.add(row);
    }
    l.print(std::cout);
}

/// Nested leave-one-family-out (analysis/validation.h), the headline: each scene family predicted
/// by a model whose whole selection ran without it; stored with the run (model_validation). Then
/// the refit-only figure of fit_cost_models, labelled as such.
void print_nested_loso(Database& db, std::int64_t run, OverRepetitions how, const ModelInputs& inputs,
                       const std::vector<StructureModels>& models) {
    const std::vector<FrameObservation> frames = load_observations(db, run, how);
    const BootstrapOptions no_bootstrap{0, 0};
    const std::vector<ValidationGroup> groups =
        validate_nested(frames, inputs, family_out_splits(frames), no_bootstrap);
    std::cout << "\nNested leave-one-family-out (the headline): for each scene family the whole model selection "
                 "(candidate form, dropped terms) is redone on the other families' frames, its inner k-fold over "
                 "families too, and the family predicted by the model so chosen; a cell it cannot price is a miss. "
                 "Absolute relative error per (scene x configuration) cell "
                 "of the median time per frame (update + rays x C) and of the median ray-cast time per frame; "
                 "median and p90 over cells; outside range: cells whose changes per frame, objects, N_RB, N_T or "
                 "(where the model prices hits) N_TP per "
                 "ray lie beyond twice (or below half) the range the model was fitted on (rcbench validate: bootstrap "
                 "intervals and the other splits):\n";
    std::map<std::pair<std::string, std::string>, double> per_scene;
    if (!groups.empty()) {
        store_validation(db, run, "nested", run_uuid(db, run), groups.front(), no_bootstrap);
        per_scene = scene_frame_errors(groups.front().cells);
        validation_table(groups.front(), "").print(std::cout);
    } else {
        std::cout << "(one scene family: none to leave out)\n";
    }
    std::vector<std::string> scenes, families;
    for (const FrameObservation& f : frames)
        if (std::find(scenes.begin(), scenes.end(), f.scene) == scenes.end()) scenes.push_back(f.scene);
    for (const StructureModels& s : models)
        for (const SceneError& x : s.loso)
            if (std::find(families.begin(), families.end(), x.scene) == families.end()) families.push_back(x.scene);
    std::cout << "\nNested leave-one-family-out error per scene (time per frame, mean over the scene's "
                 "configurations; '-': not predictable):\n";
    print_scene_table(models, scenes, [&](const StructureModels& s, const std::string& scene) {
        const auto it = per_scene.find({s.structure, scene});
        return it == per_scene.end() ? std::string("-") : percent(it->second);
    });
    std::cout << "\nLeave-one-family-out error per family, refit only (time per frame; the model chosen on all "
                 "families, only its coefficients refitted without the family: optimistic, the family helped choose "
                 "the model; '-': no other family measured the structure):\n";
    print_scene_table(models, families, [](const StructureModels& s, const std::string& scene) {
        std::string cell = "";
        for (const SceneError& x : s.loso)
            if (x.scene == scene) cell = percent(x.frame_error);
        return cell;
    });
}

/// Per structure and query kind (analysis/query_kinds.h): the chosen ray-cast model pricing each
/// kind's batches from their own counters. Nothing when the run has no kinds.
void print_kind_table(Database& db, std::int64_t run, const std::vector<StructureModels>& models) {
    if (!run_has_frame_kinds(db, run)) return;
    std::cout << "\nPer query kind: each kind's batches (frame_kind; a frame without kinds is one all-hits batch) "
                 "priced by the structure's chosen ray-cast model from the batch's own counters; time per query in "
                 "us, median over the batches; error: median over (scene x configuration) cells of |predicted - "
                 "measured| / measured ray cast per frame (rcbench validate: intervals and kind transfer):\n";
    TextTable t({"structure", "query kind", "batches", "measured us/query", "predicted us/query", "error"});
    for (const KindSummary& k : kind_summaries(models, load_kind_observations(db, run)))
        t.add({k.structure, k.kind, std::to_string(k.batches), format_us(k.ns_per_query / 1e3),
               format_us(k.predicted_ns_per_query / 1e3), percent(k.median_error)});
    t.print(std::cout);
}

/// The two runs' agreement over every cell, for each figure a run can give a cell (the median of its
/// repetitions, the figure the tables show; each frame's fastest; fastest ray cast and median
/// update: analysis/repetitions.h), then the update's band by band of its size, in `reading`.
void print_between_runs(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b, OverRepetitions reading) {
    std::cout << "Between the two runs, every cell both hold (relative range of the two runs' figures, p50 / p90 "
                 "over the cells):\n";
    TextTable t({"a run's figure of a cell", "cells", "frame", "ray cast", "update"});
    for (const auto& [how, label] : {std::pair{OverRepetitions::median, "median of its repetitions"},
                                     std::pair{OverRepetitions::fastest, "each frame's fastest repetition"},
                                     std::pair{OverRepetitions::fastest_cast, "fastest ray cast, median update"}}) {
        const StructureNoise n = between_runs_pooled(a, run_a, b, run_b, how);
        t.add({label, std::to_string(n.cells), noise_text(n.frame, n.frame_p90), noise_text(n.raycast, n.raycast_p90),
               noise_text(n.update, n.update_p90)});
    }
    t.print(std::cout);
    std::cout << "The update between the two runs by its size (" << repetitions_phrase(reading)
              << "; a cell's size: the geometric mean of the two runs' update per frame; share: the update's part of "
                 "the frame, median over the band's cells):\n";
    TextTable u({"update per frame", "cells", "update p50 / p90", "share of the frame"});
    for (const UpdateBand& band : between_runs_by_update(a, run_a, b, run_b, reading)) {
        const std::string from = fixed(band.from_ns / 1e3, 0), below = fixed(band.below_ns / 1e3, 0);
        u.add({band.from_ns == 0           ? "under " + below + " us"
               : std::isinf(band.below_ns) ? from + " us and over"
                                           : from + "-" + below + " us",
               std::to_string(band.cells), noise_text(band.update, band.update_p90),
               std::isfinite(band.share) ? percent(band.share) : "-"});
    }
    u.print(std::cout);
}

/// The noise column's figures, said in a sentence: within the run (its first two repetitions), or
/// between it and run `other_run` of `other` (`other_path`), each run's figure of a cell by `how`.
NoiseFloor noise_column(Database& db, std::int64_t run, Database* other, std::int64_t other_run,
                        const std::string& other_path, OverRepetitions how) {
    NoiseFloor noise = noise_floor(db, run);
    if (!other) {
        std::cout << "The noise column is within this run: its first two repetitions of each cell (at different "
                     "times, in other orders, on fresh structures, in one process); give --repeat with another run "
                     "of the same experiment for the spread between independent runs, which is larger on a shared "
                     "machine.\n";
        return noise;
    }
    noise.structures = between_runs(db, run, *other, other_run, how);
    std::cout << "The noise column is the spread between this run and run " << other_run << " of " << other_path
              << " (each run's figure of a cell, " << repetitions_phrase(how)
              << ", the same relative range, over the cells both hold); the slow column counts those cells with a "
                 "repetition measured slow in either run.\n";
    return noise;
}

/// What the fit read of run `run` and how a model is chosen.
void print_fit_heading(std::int64_t run, std::size_t frames, OverRepetitions how) {
    std::cout << "run " << run << ": " << frames << " frames ("
              << (how == OverRepetitions::median    ? "every repetition's frames"
                  : how == OverRepetitions::fastest ? "each frame of a cell once, at its fastest time over the cell's "
                                                      "repetitions"
                                                    : "each frame of a cell once, at its fastest ray cast and median "
                                                      "update over the cell's repetitions")
              << "). Ray-cast cost per ray in ns; held-out error is the mean absolute relative error on the "
                 "configurations of scene families left out of the fit (5-fold over families, leave-one-family-out "
                 "with fewer; a map's brushes and triangles, a generator's ray-mode variants are one family). Under "
                 "each chosen model, the held-out error without each of its terms. A model is chosen when its held-out "
                 "error is within max(0.5 points, "
                 "5%) of the best: the smallest such.\n";
}

}  // namespace

void add_fit_command(CLI::App& app) {
    struct Options {
        std::string db, experiment, repeat;
        std::int64_t run = 0;
        OverRepetitions repetitions = OverRepetitions::fastest_cast;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand(
        "fit",
        "Fit the cost model (thesis eq. 5.4) and update costs per structure to a run's frames\n"
        "Fit the cost model C = C_RB*N_RB + C_T*N_T + C_PREP (thesis eq. 5.4) and update costs per structure to a "
        "run's "
        "frames; choose the smallest adequate model by held-out error; store the coefficients in the database; "
        "validate it leaving one scene family out, the whole selection redone without the family (stored too); "
        "show what each kept term buys in held-out error. A run with "
        "query kinds (closest, any) adds a table per structure and kind: batches, measured and predicted time per "
        "query, error");
    cmd->add_option("db", o->db, "Results database")->required()->check(input_file());
    cmd->add_option("--experiment", o->experiment, "Fit the newest run of this experiment (default: the newest run)")
        ->check(non_empty());
    cmd->add_option("--run", o->run, "Fit this run id")->check(run_id());
    cmd->add_option(
           "--repeat", o->repeat,
           "DB[:RUN]: another run of the same experiment (its own process, another time); the noise "
           "column is then the spread between the two runs instead of between one run's repetitions, followed by "
           "the two runs' agreement over every cell and the update's by its size")
        ->check(non_empty());
    add_repetitions_option(cmd, o->repetitions);
    cmd->callback([o] {
        open_read_only(o->db);  // an existing results database, checked (fit does not create one)
        // The other run is found before anything is fitted or stored: a bad --repeat leaves the
        // database as it was.
        std::optional<RunRef> repeat;
        std::unique_ptr<Database> other;
        std::int64_t other_run = 0;
        if (!o->repeat.empty()) {
            repeat = parse_run_ref("--repeat", o->repeat);
            other = naming(*repeat, [&] { return open_read_only(repeat->path); });
            other_run = resolve_ref(*other, *repeat);
        }
        ResultStore store(o->db);  // migrates, so the fit tables exist
        const std::int64_t run = resolve_run(store.db(), o->run, o->experiment);
        if (repeat)
            note_cache_difference(run_cache(store.db(), run), o->db + ":" + std::to_string(run),
                                  run_cache(*other, other_run), repeat->path + ":" + std::to_string(other_run),
                                  std::cerr);
        const RunFit fit = fit_run(store.db(), run, o->repetitions);
        const std::vector<StructureModels>& models = fit.models;

        print_fit_heading(run, fit.frames, o->repetitions);
        for (const StructureModels& s : models) {
            std::cout << '\n' << s.structure;
            if (!s.unused_terms.empty()) {
                std::cout << " (terms always 0 here, left out:";
                for (const std::string& t : s.unused_terms) std::cout << ' ' << t;
                std::cout << ')';
            }
            std::cout << '\n';
            print_calibration(s);
            print_models(s.raycast, "ray-cast");
            if (const CandidateModel* m = s.chosen("raycast")) print_coefficients(*m, "ns per unit per ray");
            print_models(s.update, "update");
            if (const CandidateModel* m = s.chosen("update")) print_coefficients(*m, "ns per change / object / frame");
        }

        std::cout << "\nThesis Table 6.3 analog (ns per ray; the C terms from each structure's chosen model):\n";
        const BreakdownColumns columns = breakdown_columns(fit.breakdown, "x");
        std::vector<std::string> breakdown_header{"scene", "structure", "params"};
        breakdown_header.insert(breakdown_header.end(), columns.header.begin(), columns.header.end());
        TextTable t(breakdown_header);
        for (std::size_t i = 0; i < fit.breakdown.size(); ++i) {
            const CostBreakdown& b = fit.breakdown[i];
            std::vector<std::string> row{b.scene, b.structure, b.params};
            row.insert(row.end(), columns.rows[i].begin(), columns.rows[i].end());
            t.add(row);
        }
        t.print(std::cout);

        std::cout << "\nPer structure: the chosen ray-cast model and its terms; held-out error over configurations "
                     "(ray cast, 5-fold over scene families); leave-one-family-out error, refit only (each family "
                     "predicted by the model chosen on all families, its coefficients refitted on the others: time per "
                     "frame = update + rays x "
                     "C, and the ray-cast part alone; optimistic, the nested figures below are the headline); beside "
                     "them the noise, how far two measurements of a cell differ in time per frame and in ray-cast time "
                     "per frame, (max - min) / median, median and 90th percentile over the cells (\"-\": no cell was "
                     "measured twice). "
                     "Targets: <= 10% for rcbench's "
                     "structures, <= 15% for the peers.\n";
        const NoiseFloor noise =
            noise_column(store.db(), run, other.get(), other_run, repeat ? repeat->path : "", o->repetitions);
        TextTable e({"structure", "model", "terms", "held-out (families)", "LOFO refit frame", "LOFO refit ray cast",
                     repeat ? "between runs frame" : "noise frame", repeat ? "between runs ray cast" : "noise ray cast",
                     "slow cells", "status"});
        for (const StructureModels& s : models)
            if (const CandidateModel* m = s.chosen("raycast")) {
                std::string terms;
                for (const std::string& t : m->problem.terms) terms += (terms.empty() ? "" : " ") + t;
                const StructureNoise* n = noise.find(s.structure);
                e.add({s.structure, m->name, terms, percent(m->heldout_error), percent(s.loso_error),
                       percent(s.loso_raycast_error), n ? noise_text(n->frame, n->frame_p90) : "-",
                       n ? noise_text(n->raycast, n->raycast_p90) : "-", n ? std::to_string(n->slow) : "0",
                       m->fit.status()});
            }
        e.print(std::cout);
        if (noise.slow)
            std::cout << noise.slow << " of " << noise.cells
                      << " cells were measured while the calibration loop or memory probe ran more than 10% above its "
                         "run's median "
                         "(cell_state.slow)\n";
        if (repeat) print_between_runs(store.db(), run, *other, other_run, o->repetitions);
        print_kind_table(store.db(), run, models);
        print_nested_loso(store.db(), run, o->repetitions, *fit.inputs, models);
    });
}

}  // namespace rcb
