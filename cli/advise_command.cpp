// rcbench advise: measure every structure on a user's scene and recommend the one to ship.
#include <unistd.h>

#include <cmath>
#include <iostream>
#include <memory>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/table.h"
#include "core/base/error.h"
#include "tuner/advise.h"

namespace rcb {

namespace {

/// A time, or "-" where there is none (a prediction does not split update and ray cast).
std::string ms_or_dash(double ms) { return std::isfinite(ms) ? fixed(ms, 4) : "-"; }

/// A row's cost per frame: measured ± MAD, the model's prediction, or none (the pure model has none).
std::string per_frame_text(const AdviceRow& r) {
    if (!r.priced()) return "- (no cost model, not timed)";
    if (r.predicted) return fixed(r.cost.ms, 4) + " predicted";
    return fixed(r.cost.ms, 4) + " ± " + fixed(r.cost.mad, 4);
}

/// The measured (or, for the pure model, predicted) rows as a table, the recommendation and its
/// runner-up.
void print_rows(const Advice& advice, const AdviseOptions& options) {
    const std::vector<AdviceRow>& rows = advice.rows;
    const bool verified = options.accuracy.needs_verification();
    std::vector<std::string> header{"structure",    "parameters", "update ms", "ray cast ms",
                                    "per frame ms", "memory",     ""};
    if (verified) header.insert(header.end(), {"precision", "recall"});
    TextTable t(header);
    for (const AdviceRow& r : rows) {
        std::vector<std::string> row{r.structure,
                                     r.params,
                                     ms_or_dash(r.cost.update_ms),
                                     ms_or_dash(r.cost.raycast_ms),
                                     per_frame_text(r),
                                     std::isfinite(r.cost.memory_bytes) ? bytes_text(r.cost.memory_bytes) : "-",
                                     std::string(r.tuned ? "tuned" : "defaults") + (!r.priced() ? ", not ranked"
                                                                                    : r.meets   ? ""
                                                                                                : ", fails")};
        if (verified) row.insert(row.end(), {fixed(r.cost.accuracy.precision, 3), fixed(r.cost.accuracy.recall, 3)});
        t.add(row);
    }
    t.print(std::cout);
    if (!advice.recommended)
        throw InputError(options.scene + ": no configuration meets --accuracy " + options.accuracy.text());
    const AdviceRow& best = rows[*advice.recommended];
    if (best.predicted)
        std::cout << "\nShip " << best.structure << " " << best.params << ": " << fixed(best.cost.ms, 4)
                  << " ms per frame predicted by the cost model, nothing timed on the scene (--verify-top 0); "
                     "structures without a cost model are not ranked.";
    else
        std::cout << "\nShip " << best.structure << " " << best.params << ": " << fixed(best.cost.ms, 4)
                  << " ms per frame (update " << fixed(best.cost.update_ms, 4) << " + ray cast "
                  << fixed(best.cost.raycast_ms, 4) << "), " << bytes_text(best.cost.memory_bytes)
                  << (verified ? ", precision " + fixed(best.cost.accuracy.precision, 3) + ", recall " +
                                     fixed(best.cost.accuracy.recall, 3)
                               : std::string())
                  << "; meets " << options.accuracy.text() << ".";
    for (std::size_t i = *advice.recommended + 1; i < rows.size(); ++i)
        if (rows[i].meets) {
            std::cout << " Runner-up: " << rows[i].structure << ", " << fixed(rows[i].cost.ms / best.cost.ms, 2)
                      << "x its cost.";
            break;
        }
    std::cout << '\n';
}

std::string percent_text(double gap) { return (gap >= 0 ? "+" : "") + fixed(100 * gap, 1) + "%"; }

/// Per tuned structure, what advise measured and replayed to choose its parameters, beside the
/// size of its space (what measuring every configuration would take).
void print_budget(const std::vector<ParameterChoice>& choices, std::uint32_t repetitions) {
    if (choices.empty()) return;
    std::cout << "\nBudget per tuned structure (timed configurations, each run --repetitions " << repetitions
              << " times; counting replays, no ray timed, and of them those that timed the scene's update "
                 "(the tuning holds no update prices); the space's configurations, none merged):\n";
    TextTable t({"structure", "timed configurations", "timed measurements", "counting replays",
                 "replays timing the update", "space"});
    for (const ParameterChoice& pc : choices)
        t.add({pc.structure, std::to_string(pc.budget.timed), std::to_string(pc.budget.timed_measurements),
               std::to_string(pc.budget.replays), std::to_string(pc.budget.replays_update_timed),
               std::to_string(pc.budget.space)});
    t.print(std::cout);
}

/// --exhaustive, per structure: advise (as measured, and its steps on the table), the pure model,
/// the category's parameters and the baselines of advise's budget, each chosen, then re-measured.
void print_methods(const std::vector<ExhaustiveAdvice>& exhaustive, std::uint64_t seed) {
    std::cout << "\nEach method's choice and its budget (configurations timed, counting replays), scored on the "
                 "re-measurement after every choice (regret: its re-measured cost over the re-measured cost of "
                 "the table's best, minus 1). Random and descent: no model, advise's timed configurations and "
                 "replays (a replay tells them which configurations are one structure in effect), chosen on the "
                 "table, as advise-table takes advise's steps on it; random seed "
              << seed << ":\n";
    TextTable t({"structure", "method", "timed", "replays", "parameters", "table ms", "re-measured ms", "regret"});
    for (const ExhaustiveAdvice& x : exhaustive)
        for (const MethodOutcome& m : x.methods)
            t.add({x.structure, m.method, std::to_string(m.timed), std::to_string(m.replays), searched_text(m.searched),
                   fixed(m.table_ms, 4), fixed(m.ms, 4), percent_text(m.regret)});
    t.print(std::cout);
}

/// --exhaustive: how far the advised and the category's parameters are from the scene's best.
void print_exhaustive(const std::vector<ExhaustiveAdvice>& exhaustive) {
    if (exhaustive.empty()) return;
    std::cout << "\nEvery configuration of the tuned spaces measured on this scene (the table); the table's best, "
                 "the advised and the category's parameters re-measured after the choices, the gaps on that:\n";
    TextTable e({"structure", "configurations", "scene's best", "table ms", "re-measured ms", "advised", "gap",
                 "category's", "gap"});
    for (const ExhaustiveAdvice& x : exhaustive)
        e.add({x.structure, std::to_string(x.configurations), searched_text(x.best_searched), fixed(x.best_table_ms, 4),
               fixed(x.best_ms, 4), searched_text(x.advised_searched), percent_text(x.advised_gap()),
               searched_text(x.category_searched), percent_text(x.category_gap())});
    e.print(std::cout);
}

/// The advice as advise prints it: one JSON object, or the category, the parameter choices and tables.
void print_advice(const Advice& advice, const AdviseOptions& options, bool as_json) {
    if (as_json) {
        std::cout << advice_json(advice, options).dump(2) << '\n';
        if (!advice.recommended)
            throw InputError(options.scene + ": no configuration meets --accuracy " + options.accuracy.text());
        return;
    }
    std::cout << advice.workload_text << "\n\n";
    if (advice.chosen) std::cout << "Scene " << options.scene << " -> " << advice.chosen->explanation << "\n\n";
    for (const ParameterChoice& pc : advice.parameters) std::cout << pc.summary << '\n';
    if (!advice.parameters.empty()) std::cout << '\n';
    print_rows(advice, options);
    print_budget(advice.parameters, options.repetitions);
    print_exhaustive(advice.exhaustive);
    if (!advice.exhaustive.empty()) print_methods(advice.exhaustive, advice.baseline_seed);
}

}  // namespace

void add_advise_command(CLI::App& app) {
    auto o = std::make_shared<AdviseOptions>();
    CLI::App* cmd =
        app.add_subcommand("advise",
                           "Recommend the structure and parameters to ship for a scene, measured or predicted\n"
                           "Measure every registered structure on a scene (recording or boxes CSV) at its tuned or "
                           "default parameters, and recommend the one to ship (--verify-top 0: predict them by the "
                           "tuning's cost model instead, timing nothing); prints what choosing the tuned parameters "
                           "spent (timed configurations, counting replays) beside the space's size");
    cmd->add_option("scene", o->scene,
                    "Recording (.rcbscene) or boxes CSV (given 10 frames of 1% dynamics and 1000 centre rays)")
        ->required()
        ->check(input_file());
    cmd->add_option("--tuning", o->tuning,
                    "A tuner's results (results/tuning-<name>.json): use its parameters for --category, or without "
                    "--category for the category whose centroid is nearest this scene's features")
        ->check(input_file());
    cmd->add_option("--category", o->category,
                    "Which category of the tuning file this scene resembles (default: chosen from the scene's "
                    "features)")
        ->check(non_empty());
    cmd->add_option("--method", o->method,
                    "How a tuned structure's parameters are chosen for this scene: category (the category's tuned "
                    "parameters as they are), model (the category's cost model, fitted while tuning, applied to this "
                    "scene's own counters: counting replays of the tuning's space, the best measured beside the "
                    "category's parameters), auto (model where the tuning holds one, else category)")
        ->capture_default_str()
        ->check(CLI::IsMember({"auto", "category", "model"}));
    cmd->add_option("--verify-top", o->verify_top,
                    "Model method: how many of its best predicted configurations are measured on the scene beside "
                    "the category's parameters (configurations the replays count alike, one structure in effect, "
                    "once); the fastest measured is advised. 0: the pure model, nothing timed on the scene: the "
                    "predicted best is advised, every row is the model's prediction (a structure without a cost "
                    "model is not ranked), and the replays predict the update from the tuning's update prices "
                    "(a tuning without them times the update in each replay, as the budget reports); needs "
                    "--accuracy exact")
        ->capture_default_str()
        ->check(whole_number(0, 16));
    cmd->add_option("--refine", o->refine,
                    "Model method: at most this many more measurements, a descent from the fastest verified "
                    "configuration one level of one parameter at a time (two where one finds nothing) while a "
                    "neighbour is faster (corrects what the model misranks; 0: none, and none with --verify-top 0)")
        ->capture_default_str()
        ->check(whole_number(0, 64));
    cmd->add_option("--replays", o->replays,
                    "Model method: at most this many counting replays of each tuned structure's space on the "
                    "scene, ranked by the model (default: the tuning's search budget); a space no larger is "
                    "replayed whole. Replays time nothing where the tuning holds update prices, so the pure "
                    "model can rank a whole space at no timed cost; --exhaustive's baselines get the same replays")
        ->check(whole_number(1, 10'000));
    CLI::Option* exhaustive = cmd->add_flag(
        "--exhaustive", o->exhaustive,
        "Also measure every configuration of each tuned structure's space on the scene and report how far "
        "the advised and the category's parameters are from the scene's own best (needs --tuning); beside "
        "them the pure-model choice (what --verify-top 0 advises) and two baselines with advise's number of "
        "timed configurations and counting replays and no model: random configurations (--seed) and a "
        "measured descent from the category's parameters. The space is measured once (the table): the "
        "baselines choose on it, advise's steps are taken again on it (row advise-table), and its best is "
        "the scene's optimum. Then every method's choice and the optimum are measured again, and each is "
        "scored on that re-measurement, so none is priced by the numbers it chose on and the optimum is not "
        "a lucky draw of its own table");
    cmd->add_option("--seed", o->seed, "Seed of --exhaustive's random baseline (default: the tuning's search seed)")
        ->check(whole_number())
        ->needs(exhaustive);
    auto json_out = std::make_shared<bool>(false);
    cmd->add_flag("--json", *json_out, "Print the advice as one JSON object instead of tables");
    cmd->add_option("--repetitions", o->repetitions, "Measurements per structure")
        ->capture_default_str()
        ->check(CLI::Range(1u, 100u));
    cmd->add_option("--warmup", o->warmup, "Frames left out of the medians")
        ->capture_default_str()
        ->check(whole_number(0, 1'000'000));
    auto accuracy = std::make_shared<std::string>("exact");
    cmd->add_option("--accuracy", *accuracy,
                    "What the recommendation must answer: exact (no mismatches at the configuration's own query "
                    "level), recall>=R or precision>=P (against the shapes; R, P in 0..1). A constraint other than "
                    "exact also measures every structure at the candidates and shapes query levels")
        ->capture_default_str();
    cmd->callback([o, accuracy, json_out] {
        AdviseOptions options = *o;
        options.accuracy = parse_accuracy(*accuracy);
        // Progress only where a person watches: off a terminal, stderr holds nothing but an error's one line.
        if (isatty(STDERR_FILENO))
            options.progress = [](const std::string& structure) { std::cerr << "measuring " << structure << " ...\n"; };
        print_advice(advise(options), options, *json_out);
    });
}

}  // namespace rcb
