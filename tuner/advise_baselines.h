#pragma once
/// What advise spends on a tuned structure, and the baselines that spend as much (advise
/// --exhaustive). A search or an advice is only evidence against a baseline with the same
/// measurement budget: here, as many timed configurations as advise measured for the structure,
/// chosen without the cost model, and priced like advise's own choice from the exhaustive table.
///
///   model    the pure-model choice: the predicted best of the replays (what --verify-top 0
///            --refine 0 advises), no measurement deciding
///   random   `budget` configurations drawn uniformly without replacement from the space
///            (seeded), the fastest of them
///   descent  a measured coordinate descent without the model, from the category's parameters:
///            first improvement over the neighbours one level away in one parameter (in the
///            space's order, up before down), two levels away where none of those is faster,
///            as advise's own refinement walks; it stops at the budget or where no neighbour is
///            faster
///
/// All of them, advise's choice and the category's parameters take their costs from the same
/// exhaustive measurements, so the comparison shares the noise and the budgets match exactly.
/// The baselines choose on a second, independent table: a method that picks the fastest of the
/// very numbers it is then scored by keeps their noise in its favour (the winner's curse), which
/// advise, choosing on measurements of its own, cannot. Those own measurements, though, were
/// taken before both tables, while the two tables are measured back to back; on a host whose speed
/// moves in stretches of minutes, the baselines' table can agree with the scoring one better than
/// advise's measurements do. So `advise-table` takes advise's steps again on the baselines' table
/// (advise_on_table, tuner/advise.h): every method in that row's company chooses on the same
/// numbers and is scored on the others.

#include <cstdint>
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
    std::size_t replays = 0;             ///< counting replays (untimed) of the scene
    std::size_t space = 0;               ///< configurations of the space as the tuning lists it (none merged)
    friend bool operator==(const AdviseBudget&, const AdviseBudget&) = default;
};

/// `count` (at most `space_size`) distinct indices of a space of `space_size`, drawn uniformly
/// without replacement: a Fisher–Yates prefix with Random(seed), the same for a seed everywhere.
std::vector<std::size_t> random_picks(std::size_t space_size, std::size_t count, std::uint64_t seed);

/// The model-free descent's measurements, in order: indices into `configurations` (the space's,
/// enumerate_space order) priced by `costs`. It starts at `start` (a level missing or not in
/// the space: the middle one, as search_levels starts) and measures at most `budget`.
std::vector<std::size_t> descent_path(const std::vector<SearchDimension>& space,
                                      const std::vector<nlohmann::json>& configurations,
                                      const std::vector<double>& costs, const nlohmann::json& start,
                                      std::size_t budget);

/// One way of choosing the structure's parameters, priced from the exhaustive table.
struct MethodOutcome {
    std::string method;     ///< advise, model, category, random, descent
    std::size_t timed = 0;  ///< timed configurations it spent (the category's: none)
    nlohmann::json searched;
    double ms = 0;      ///< from the exhaustive measurements
    double regret = 0;  ///< ms / the scene's best − 1
};

/// advise's choice made on a table (advise_on_table, tuner/advise.h): its searched parameters and
/// the distinct configurations it read.
struct TableChoice {
    nlohmann::json searched;
    std::size_t timed = 0;
};

/// What compare_methods needs: the exhaustive table and each method's inputs.
struct MethodInputs {
    std::vector<SearchDimension> space;
    std::vector<nlohmann::json> configurations;  ///< enumerate_space(space)
    std::vector<double> costs;         ///< per configuration, accuracy priced in: what every method is priced by
    std::vector<double> choice_costs;  ///< what the baselines choose by (an independent table; empty: `costs`)
    nlohmann::json advised, category;  ///< searched parameters
    /// advise's steps taken on `choice_costs`; none where advise measured nothing (the category
    /// method, --verify-top 0) or a step needed a configuration the table lacks.
    std::optional<TableChoice> advised_on_table;
    std::optional<nlohmann::json> predicted_best;  ///< the model method's; none for the category method
    std::size_t budget = 0;                        ///< advise's timed configurations
    std::uint64_t seed = 1;                        ///< the random baseline's
};

/// advise, advise on the baselines' table (`advise-table`, when given), the pure model (when
/// there is one), the category's parameters, random and descent, in that order; a method whose
/// configuration is not in the table (a category level the space lacks) or that measured nothing
/// (a budget of 0) has no row.
std::vector<MethodOutcome> compare_methods(const MethodInputs& inputs);

}  // namespace rcb
