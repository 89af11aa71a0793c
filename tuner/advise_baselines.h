#pragma once
/// What advise spends on a tuned structure, and the baselines that spend as much (advise
/// --exhaustive). A search or an advice is only evidence against a baseline with the same budget:
/// here as many timed configurations and as many counting replays as advise spent on
/// the structure, chosen without the cost model.
///
///   model    the pure-model choice: the predicted best of the replays (what --verify-top 0
///            advises), nothing timed
///   random   configurations drawn uniformly without replacement from the space (seeded): as many
///            replayed as advise replayed, and of those, in the order drawn, one per structure in
///            effect (equal counts) timed until advise's timed count is spent; the fastest of them
///   descent  a measured coordinate descent without the model, from the category's parameters:
///            first improvement over the neighbours one level away in one parameter (in the
///            space's order, up before down), two levels away where none of those is faster,
///            as advise's own refinement walks; while replays remain, a neighbour is replayed
///            first and not timed where it counts like one timed already (as advise skips it); it
///            stops at the timed budget or where no neighbour is faster
///
/// Scoring is independent of choosing. Every method that chooses on measurements chooses on one
/// table (the space measured once: the baselines, and `advise-table`, advise's own steps taken
/// again on it), and the scene's optimum is that table's best. Then a separate timing pass
/// re-measures each method's choice and the optimum, and regret is the re-measured cost over the
/// re-measured optimum's, minus 1. A method scored by the numbers it chose on keeps their noise in
/// its favour (the winner's curse), and an optimum read from the same table as its own cost is a
/// lucky draw that makes every other choice look worse; the second pass removes both. A regret
/// below 0 says that the choice beat the table's optimum on the re-measurement: noise, or a
/// near-tie.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tuner/search.h"

namespace rcb {

/// advise's measurements of one tuned structure on the scene.
struct AdviseBudget {
    std::size_t timed = 0;               ///< distinct configurations timed (the rows' included)
    std::size_t timed_measurements = 0;  ///< timed runs of them: each configuration's repetitions
    std::size_t replays = 0;             ///< counting replays of the scene (no ray timed)
    /// Of the replays, those that timed the scene's update (a tuning without update prices,
    /// UpdatePrices in tuner/tuning.h); 0 where every replay was untimed.
    std::size_t replays_update_timed = 0;
    std::size_t space = 0;  ///< configurations of the space as the tuning lists it (none merged)
    friend bool operator==(const AdviseBudget&, const AdviseBudget&) = default;
};

/// `count` (at most `space_size`) distinct indices of a space of `space_size`, drawn uniformly
/// without replacement: a Fisher–Yates prefix with Random(seed), the same for a seed everywhere.
std::vector<std::size_t> random_picks(std::size_t space_size, std::size_t count, std::uint64_t seed);

/// The model-free descent's measurements, in order: indices into `configurations` (the space's,
/// enumerate_space order) priced by `costs`. It starts at `start` (a level missing or not in
/// the space: the middle one, as search_levels starts) and measures at most `budget`. With
/// `class_of` (structures in effect per configuration, from replays), up to `replays`
/// configurations are replayed before they would be measured, and one that is a structure
/// measured already is passed over; `replayed` receives how many it replayed.
std::vector<std::size_t> descent_path(const std::vector<SearchDimension>& space,
                                      const std::vector<nlohmann::json>& configurations,
                                      const std::vector<double>& costs, const nlohmann::json& start, std::size_t budget,
                                      const std::vector<std::size_t>& class_of = {}, std::size_t replays = 0,
                                      std::size_t* replayed = nullptr);

/// The random baseline's picks: `replays` configurations drawn (random_picks, seed), and of them,
/// in the order drawn, the first of each structure in effect (`class_of`) until `budget` are
/// timed. Without replays (or classes), the first `budget` drawn. Indices into the space.
std::vector<std::size_t> random_timed(std::size_t space_size, std::size_t budget, std::size_t replays,
                                      const std::vector<std::size_t>& class_of, std::uint64_t seed);

/// One way of choosing the structure's parameters (choose_methods); scored, its re-measured cost.
struct MethodOutcome {
    std::string method;       ///< advise, advise-table, model, category, random, descent
    std::size_t timed = 0;    ///< timed configurations it spent choosing (the category's, the model's: none)
    std::size_t replays = 0;  ///< counting replays it spent choosing
    std::size_t index = 0;    ///< its choice among the configurations
    nlohmann::json searched;
    double table_ms = 0;  ///< the choice in the table the methods chose on
    double ms = 0;        ///< re-measured after the choice (the scoring pass)
    double regret = 0;    ///< ms / the optimum's re-measured ms − 1
};

/// advise's choice made on a table (advise_on_table, tuner/advise.h): its searched parameters and
/// the distinct configurations it read.
struct TableChoice {
    nlohmann::json searched;
    std::size_t timed = 0;
    std::size_t replays = 0;  ///< counting replays it rests on: the ranking's and the descent's
};

/// What compare_methods needs: the table the methods choose on and each method's inputs.
struct MethodInputs {
    std::vector<SearchDimension> space;
    std::vector<nlohmann::json> configurations;  ///< enumerate_space(space)
    /// Per configuration, accuracy priced in (constrained_cost): the table the baselines and
    /// advise-table choose on, whose best is the scene's optimum.
    std::vector<double> table;
    /// Structures in effect per configuration (equality_classes of the scene's replays; empty:
    /// none), what the baselines' replays tell them.
    std::vector<std::size_t> class_of;
    nlohmann::json advised, category;  ///< searched parameters
    /// advise's steps taken on `choice_costs`; none where advise measured nothing (the category
    /// method, --verify-top 0) or a step needed a configuration the table lacks.
    std::optional<TableChoice> advised_on_table;
    std::optional<nlohmann::json> predicted_best;  ///< the model method's; none for the category method
    std::size_t budget = 0;                        ///< advise's timed configurations
    std::size_t replays = 0;                       ///< advise's counting replays
    std::uint64_t seed = 1;                        ///< the random baseline's
};

/// The methods' choices, unscored: advise, advise on the table (`advise-table`, when given), the
/// pure model (when there is one), the category's parameters, random and descent, in that order;
/// a method whose configuration is not in the table (a category level the space lacks) or that
/// measured nothing (a budget of 0) has no row. `optimum` receives the table's best.
std::vector<MethodOutcome> choose_methods(const MethodInputs& inputs, std::size_t& optimum);

/// The configurations a scoring pass re-measures: the optimum first, then each choice once.
std::vector<std::size_t> to_rescore(const std::vector<MethodOutcome>& choices, std::size_t optimum);

/// The methods scored on `rescored` (per configuration; only those of to_rescore are read), their
/// regret against the optimum's re-measured cost.
void score_methods(std::vector<MethodOutcome>& choices, std::size_t optimum, const std::vector<double>& rescored);

/// choose_methods then score_methods with `rescore` (indices → their re-measured costs, in
/// order), which is called once, after every choice is made.
struct MethodComparison {
    std::vector<MethodOutcome> methods;
    std::size_t optimum = 0;
    double optimum_table_ms = 0, optimum_ms = 0;  ///< in the table and re-measured
};
MethodComparison compare_methods(const MethodInputs& inputs,
                                 const std::function<std::vector<double>(const std::vector<std::size_t>&)>& rescore);

}  // namespace rcb
