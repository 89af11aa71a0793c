// rcbench validate: the cost model predicting what it never saw. With --test, the model chosen and
// fitted on one run prices every cell of another, and each of its query kinds' batches; without,
// the run's nested splits (each split's whole model selection redone on its train frames only).
#include <iostream>
#include <cmath>
#include <memory>
#include <optional>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/run_ref.h"
#include "analysis/noise.h"
#include "analysis/query_kinds.h"
#include "analysis/validation.h"
#include "core/base/error.h"
#include "runner/store.h"
#include "cli/validation_table.h"

namespace rcb {
namespace {

/// What one run gives the validation: its id, uuid, frames and (for a train run) calibration and caches.
struct LoadedRun {
    std::int64_t run = 0;
    std::string uuid;
    std::vector<FrameObservation> frames;
    ModelInputs inputs;
};

LoadedRun load_run(Database& db, const RunRef& ref, OverRepetitions how) {
    return naming(ref, [&] {
        LoadedRun out;
        out.run = resolve_ref(db, ref);
        out.uuid = run_uuid(db, out.run);
        out.frames = load_observations(db, out.run, how);
        out.inputs = load_model_inputs(db, out.run);
        return out;
    });
}

void print_group(const ValidationGroup& g) {
    std::cout << '\n' << g.name << " (" << g.splits.size() << (g.splits.size() == 1 ? " split" : " splits") << ")\n";
    validation_table(g, "  ").print(std::cout);
}

void print_header(const BootstrapOptions& b) {
    std::cout << "Absolute relative error per (scene x configuration) cell of the median time per frame (update + "
                 "rays x C) and of the median ray-cast time per frame; median and p90 over cells per structure, "
                 "in brackets the bootstrap 95% interval over scenes ("
              << b.resamples << " resamples, seed " << b.seed
              << "). Misses: cells measured but not priced (a structure without a model in the split, or a "
                 "model without a column for the cell); each counts as an error beyond any bound in the median and "
                 "p90 (\"miss\" where a quantile falls on them), and their share of the cells is given. Scenes are "
                 "held out by family (a map's brushes and triangles, a generator's ray-mode variants: docs/model.md), "
                 "in the outer splits and in each split's own model selection. Outside range: predicted cells whose "
                 "changes per frame, objects, "
                 "N_RB or N_T per ray (or N_TP, where the model prices hits) lie beyond twice (or below half) "
                 "the range of the cells the model was fitted "
                 "on: priced by extrapolation (--json names the counters).\n";
}

/// The per-kind part of the nested validation (analysis/query_kinds.h): the run's model priced on
/// each kind's counters, and the kind-transfer group (stored); `absent` says why there is none.
struct KindValidation {
    std::vector<KindError> check;
    std::vector<ValidationGroup> groups;
    std::string absent;
};

KindValidation validate_kinds(ResultStore& store, const LoadedRun& run, const BootstrapOptions& bootstrap) {
    KindValidation out;
    if (!run_has_frame_kinds(store.db(), run.run)) {
        out.absent = "the run has no query kinds (no frame_kind rows: every ray asked for all hits)";
        return out;
    }
    const std::vector<FrameObservation> kind_frames = load_kind_observations(store.db(), run.run);
    out.check = kind_errors(kind_cells(fit_cost_models(run.frames, run.inputs), kind_frames));
    const std::vector<ValidationSplit> splits = kind_transfer_splits(kind_frames);
    if (splits.empty()) {
        out.absent = "every batch of the run asked for one query kind: nothing to transfer to";
        return out;
    }
    out.groups = validate_nested(kind_frames, run.inputs, splits, bootstrap);
    for (const ValidationGroup& g : out.groups) store_validation(store.db(), run.run, "nested", run.uuid, g, bootstrap);
    return out;
}

nlohmann::json kinds_json(const KindValidation& k) {
    nlohmann::json check = nlohmann::json::array();
    for (const KindError& e : k.check)
        check.push_back({{"structure", e.structure},
                         {"kind", e.kind},
                         {"cells", e.cells},
                         {"raycast_error_median",
                          std::isfinite(e.median_error) ? nlohmann::json(e.median_error) : nlohmann::json(nullptr)}});
    return {{"model_per_kind", check},
            {"kind_transfer", k.absent.empty() ? nlohmann::json("present") : nlohmann::json("absent: " + k.absent)}};
}

void print_kinds(const KindValidation& k) {
    if (!k.check.empty()) {
        std::cout << "\nquery kinds: the run's model (fitted on whole frames) pricing each kind's batch from its own "
                     "counters; median over (scene x configuration) cells of |predicted - measured| / measured "
                     "ray cast per frame\n";
        TextTable t({"  structure", "query kind", "cells", "median error"});
        for (const KindError& e : k.check)
            t.add({"  " + e.structure, e.kind, std::to_string(e.cells), percent(e.median_error)});
        t.print(std::cout);
    }
    if (!k.absent.empty()) std::cout << "\n" << kKindTransferGroup << ": absent, " << k.absent << '\n';
}

/// The test run's kind batches priced by the train run's frozen model (analysis/query_kinds.h),
/// stored with the test run's other groups; `absent` says why there are none.
struct FrozenKinds {
    std::vector<ValidationGroup> groups;
    std::string absent;
};

FrozenKinds validate_test_kinds(Database& db, std::int64_t test_run, const std::vector<StructureModels>& models,
                                const BootstrapOptions& bootstrap) {
    FrozenKinds out;
    if (!run_has_frame_kinds(db, test_run)) {
        out.absent = "the test run has no query kinds (no frame_kind rows: every ray asked for all hits)";
        return out;
    }
    out.groups = validate_frozen_kinds(models, load_kind_observations(db, test_run), bootstrap);
    return out;
}

nlohmann::json frozen_kinds_json(const FrozenKinds& k) {
    nlohmann::json names = nlohmann::json::array();
    for (const ValidationGroup& g : k.groups) names.push_back(g.name);
    return {{"per_kind_groups", names},
            {"per_kind", k.absent.empty() ? nlohmann::json("present") : nlohmann::json("absent: " + k.absent)}};
}

void print_frozen_kinds(const FrozenKinds& k) {
    if (!k.absent.empty()) {
        std::cout << "\nper query kind: absent, " << k.absent << '\n';
        return;
    }
    std::cout << "\nper query kind (groups " << kKindGroupPrefix
              << "KIND): the train run's model pricing each kind's batches of the test run from their own counters; "
                 "absolute relative error of the median ray-cast time of the batch per frame per (scene x "
                 "configuration) cell, median and p90 over cells with bootstrap 95% intervals over scenes\n";
    kind_validation_table(k.groups, "  ").print(std::cout);
}

struct ValidateOptions {
    std::string train, test, repeat;
    bool json = false;
    BootstrapOptions bootstrap;
    OverRepetitions repetitions = OverRepetitions::fastest_cast;
};

/// What one validation gives to print: the groups in order and, per path, the query kinds' part.
struct ValidateOutcome {
    std::vector<ValidationGroup> groups;
    std::vector<std::string> unpredictable;
    std::int64_t predicted_run = 0, train_run = 0;
    std::optional<KindValidation> kinds;  // nested splits only
    std::optional<FrozenKinds> frozen;    // --test only
    std::vector<StructureNoise> spread;   // --repeat only: between the predicted run and the repeat
};

/// The run --repeat names: opened and found before anything is computed or stored.
struct RepeatRun {
    std::unique_ptr<Database> db;
    std::int64_t run = 0;
    std::string name;  ///< "B.db:2"
};

/// The predicted run's spread against the repeat, per structure (analysis/noise.h): each run's
/// figure of a cell read as the validation reads it.
std::vector<StructureNoise> spread_against(Database& db, std::int64_t run, const RepeatRun* repeat,
                                           OverRepetitions how) {
    if (!repeat) return {};
    note_cache_difference(run_cache(db, run), db.path() + ":" + std::to_string(run),
                          run_cache(*repeat->db, repeat->run), repeat->name, std::cerr);
    return between_runs(db, run, *repeat->db, repeat->run, how);
}

/// Without --test: the train run's nested splits, stored with it.
ValidateOutcome validate_nested_run(const RunRef& train_ref, const BootstrapOptions& bootstrap, OverRepetitions how,
                                    const RepeatRun* repeat) {
    ValidateOutcome out;
    ResultStore store = naming(train_ref, [&] { return ResultStore(train_ref.path); });  // stored with the run
    const LoadedRun train = load_run(store.db(), train_ref, how);
    out.predicted_run = out.train_run = train.run;
    out.groups = validate_nested(train.frames, train.inputs, nested_splits(train.frames), bootstrap);
    out.groups.push_back(validate_calibration_only(train.frames, train.inputs, bootstrap));
    for (const ValidationGroup& g : out.groups)
        store_validation(store.db(), train.run, "nested", train.uuid, g, bootstrap);
    out.kinds = validate_kinds(store, train, bootstrap);
    out.groups.insert(out.groups.end() - 1, out.kinds->groups.begin(), out.kinds->groups.end());
    out.spread = spread_against(store.db(), train.run, repeat, how);
    return out;
}

/// With --test: the train run's frozen model on every cell of the test run, and on each of its
/// query kinds' batches; stored in the test database. The per-kind groups are printed apart
/// (print_frozen_kinds) and join the JSON groups before calibration-only.
ValidateOutcome validate_test_run(const RunRef& train_ref, const RunRef& test_ref, const BootstrapOptions& bootstrap,
                                  OverRepetitions how, const RepeatRun* repeat) {
    ValidateOutcome out;
    LoadedRun train;
    std::string train_cache;
    {
        auto db = naming(train_ref, [&] { return open_read_only(train_ref.path); });
        train = load_run(*db, train_ref, how);
        train_cache = run_cache(*db, train.run);
    }
    ResultStore store = naming(test_ref, [&] { return ResultStore(test_ref.path); });
    const LoadedRun test = load_run(store.db(), test_ref, how);
    note_cache_difference(train_cache, train_ref.path + ":" + std::to_string(train.run),
                          run_cache(store.db(), test.run), test_ref.path + ":" + std::to_string(test.run), std::cerr);
    out.predicted_run = test.run;
    out.train_run = train.run;
    const std::string train_name = train_ref.path + ":" + std::to_string(train.run);
    const std::vector<StructureModels> models = fit_cost_models(train.frames, train.inputs);
    TransferValidation v = validate_transfer(models, test.frames, bootstrap);
    store_validation(store.db(), test.run, train_name, train.uuid, v.group, bootstrap);
    out.groups.push_back(std::move(v.group));
    out.unpredictable = v.unpredictable;
    out.frozen = validate_test_kinds(store.db(), test.run, models, bootstrap);
    for (const ValidationGroup& g : out.frozen->groups)
        store_validation(store.db(), test.run, train_name, train.uuid, g, bootstrap);
    // The test run's own calibration (its machine's micro-scenes), no frames fitted.
    out.groups.push_back(validate_calibration_only(test.frames, test.inputs, bootstrap));
    store_validation(store.db(), test.run, "calibration", test.uuid, out.groups.back(), bootstrap);
    out.spread = spread_against(store.db(), test.run, repeat, how);
    return out;
}

void print_json(const ValidateOptions& o, const ValidateOutcome& r) {
    nlohmann::json j{{"run", r.predicted_run},
                     {"train", o.train},
                     {"train_run", r.train_run},
                     {"test", o.test.empty() ? nlohmann::json(nullptr) : nlohmann::json(o.test)},
                     {"bootstrap", {{"resamples", o.bootstrap.resamples}, {"seed", o.bootstrap.seed}}},
                     {"repetitions", repetitions_name(o.repetitions)},
                     {"not_predictable", r.unpredictable},
                     {"groups", nlohmann::json::array()}};
    for (const ValidationGroup& g : r.groups) {
        if (r.frozen && g.name == kCalibrationGroup)  // the per-kind groups before calibration alone
            for (const ValidationGroup& k : r.frozen->groups) j["groups"].push_back(validation_json(k, true));
        j["groups"].push_back(validation_json(g, true));
    }
    if (!o.repeat.empty()) {
        j["repeat"] = o.repeat;
        j["between_runs"] = nlohmann::json::array();
        for (const StructureNoise& n : r.spread)
            j["between_runs"].push_back(
                {{"structure", n.structure},
                 {"cells", n.cells},
                 {"frame_median", std::isfinite(n.frame) ? nlohmann::json(n.frame) : nullptr},
                 {"frame_p90", std::isfinite(n.frame_p90) ? nlohmann::json(n.frame_p90) : nullptr}});
    }
    if (r.kinds) j["query_kinds"] = kinds_json(*r.kinds);
    if (r.frozen) j["query_kinds"] = frozen_kinds_json(*r.frozen);
    std::cout << j.dump(2) << '\n';
}

void print_text(const ValidateOptions& o, const ValidateOutcome& r) {
    std::cout << (o.test.empty()
                      ? "run " + std::to_string(r.predicted_run) + ": nested splits. "
                      : "run " + std::to_string(r.predicted_run) + " of " + o.test + " predicted by the model of run " +
                            std::to_string(r.train_run) + " of " + o.train + ". ");
    std::cout << "A cell's repetitions: " << repetitions_name(o.repetitions) << ". ";
    print_header(o.bootstrap);
    if (r.groups.empty()) std::cout << "no split applies: the run has one scene\n";
    for (const ValidationGroup& g : r.groups) print_group(g);
    if (!o.repeat.empty() && !r.groups.empty()) {
        std::cout << "\n"
                  << r.groups.front().name << " beside the spread between run " << r.predicted_run << " and the repeat "
                  << o.repeat
                  << ": the frame error (above) and how far the two runs measure the same cell, (max - min) / median "
                     "of the two runs' time per frame, median and p90 over the cells both hold; ratio: error over "
                     "spread (at most 1: the model is as close as a rerun)\n";
        spread_table(r.groups.front(), r.spread, "  ").print(std::cout);
    }
    if (r.kinds) print_kinds(*r.kinds);
    if (r.frozen) print_frozen_kinds(*r.frozen);
    if (!r.unpredictable.empty()) {
        std::cout << "\nnot predictable (not measured in the train run):";
        for (const std::string& s : r.unpredictable) std::cout << ' ' << s;
        std::cout << '\n';
    }
}

}  // namespace

void add_validate_command(CLI::App& app) {
    auto o = std::make_shared<ValidateOptions>();
    CLI::App* cmd = app.add_subcommand(
        "validate",
        "Validate the cost model on scenes it never saw, beside the spread between two runs\n"
        "Validate the cost model on what it never saw. With --test: the model form and coefficients chosen and "
        "fitted on the train run (all its scenes) predict every cell of the test run from its counters; stored in "
        "the test database (table model_validation); a test run with query kinds adds one group per kind (kind:all, "
        "kind:closest, kind:any: the frozen model pricing that kind's batches from their own counters, ray-cast error "
        "only), a test run without says they are absent. Without --test: the train run's nested splits (leave one "
        "scene family out, one scene category out, the largest scenes out, ray-mode transfer), each split's whole "
        "model "
        "selection redone on its train frames only; stored in the train database. A run with query kinds (closest, "
        "any) adds kind transfer (a model fitted on the all-hits batches predicting the closest and any batches, and "
        "back) and the run's model priced on each kind's counters; a run without says the group is absent. Per "
        "structure: median and p90 over "
        "(scene x configuration) cells of the absolute relative error of time per frame and of ray-cast time per "
        "frame, with bootstrap 95% intervals over scenes. Both end with calibration alone: the predicted run's ray "
        "casts priced by its own micro-scene calibration (rcbench run's calibration pass), nothing fitted on any "
        "experiment's frames (ray cast only: the calibration does not measure updates)");
    cmd->add_option("--train", o->train,
                    "DB[:RUN]: the run the model is chosen and fitted on (default: its newest run with cells)")
        ->required();
    cmd->add_option("--test", o->test, "DB[:RUN]: the run predicted (default: its newest run with cells)");
    cmd->add_option("--repeat", o->repeat,
                    "DB[:RUN]: another run of the same experiment on the same machine and day; the first group's "
                    "held-out frame error is printed beside the spread between it and the predicted run (the train "
                    "run, or the test run with --test) over the cells both hold")
        ->check(non_empty());
    cmd->add_flag("--json", o->json, "Print JSON (summaries and every cell's prediction) instead of tables");
    cmd->add_option("--resamples", o->bootstrap.resamples, "Bootstrap resamples over scenes")
        ->check(whole_number(1, 1000000))
        ->default_val(2000);
    cmd->add_option("--seed", o->bootstrap.seed, "Seed of the bootstrap")
        ->check(whole_number(0, std::uint64_t(std::numeric_limits<std::int64_t>::max())))
        ->default_val(1);
    add_repetitions_option(cmd, o->repetitions);
    cmd->callback([o] {
        const RunRef train_ref = parse_run_ref("--train", o->train);
        std::optional<RepeatRun> repeat;
        if (!o->repeat.empty()) {
            const RunRef ref = parse_run_ref("--repeat", o->repeat);
            repeat.emplace();
            repeat->db = naming(ref, [&] { return open_read_only(ref.path); });
            repeat->run = resolve_ref(*repeat->db, ref);
            repeat->name = ref.path + ":" + std::to_string(repeat->run);
        }
        const RepeatRun* r_ptr = repeat ? &*repeat : nullptr;
        const ValidateOutcome r = o->test.empty() ? validate_nested_run(train_ref, o->bootstrap, o->repetitions, r_ptr)
                                                  : validate_test_run(train_ref, parse_run_ref("--test", o->test),
                                                                      o->bootstrap, o->repetitions, r_ptr);
        if (o->json)
            print_json(*o, r);
        else
            print_text(*o, r);
    });
}

}  // namespace rcb
