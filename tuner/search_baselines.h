#pragma once
/// What a search is judged against: the same budget spent by a method that knows nothing, on a
/// surface where every configuration's cost is known (measured exhaustively), so every method is
/// priced by the same measurements and differs only in which configurations it picks.
///
///   random   k configurations drawn uniformly without replacement; its expected best is exact
///            (order statistics of the sorted costs), so no seed decides the comparison
///   descent  the model-free descent advise is judged against (tuner/advise_baselines.h:
///            first improvement one level away in one parameter, two where none is faster), from
///            the same start as the tuner, until no neighbour is faster or the budget is spent
///
///   ranked   the tuner's method where a model exists (rank_then_time, tuner/search.h): every
///            configuration replayed (its rays counted, not timed; its update timed) and ranked by the model, the
///            best-ranked classes timed within the same budget, the model refitted on what has been timed
///
/// Configurations that are one structure in effect (equal counts in a counting replay: a hash
/// grid of depth 0 ignores its capacity) are merged first: a class's cost is the median of its
/// members' measurements, the budget is a share of the classes, and random search draws classes.
/// So every method has the same budget: that many timed structures in effect, and the replays of
/// the whole space (the ranked method ranks by them, the others draw or walk by their classes).
///
/// Every method chooses on one measurement of the space (the table), whose best class is the
/// optimum; each is scored on a second, independent measurement taken after the first (the
/// scores): its choice's cost there over the optimum's there, minus 1. Scored on the table it
/// chose from, a method that finds the table's best has regret 0 however lucky that draw was (the
/// winner's curse), and so beats random by construction.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include "tuner/search.h"

namespace rcb {

/// The expected lowest of `k` of `costs` drawn uniformly without replacement:
/// Σ_i c_(i) · C(n − i, k − 1) / C(n, k) over the costs in ascending order (i from 1). k is
/// clamped to [1, n]; NaN for no costs.
double expected_best_of_random(std::vector<double> costs, std::size_t k);
/// The expected score (`scores`, same order) of the configuration with the lowest cost among `k`
/// drawn as above: the same weights, each on the score of the i-th lowest cost. Ties in `costs`
/// are taken in their order. NaN for no costs.
double expected_score_of_random(const std::vector<double>& costs, const std::vector<double>& scores, std::size_t k);

/// The ranked method's inputs: its predictions before any timing (the micro-scene calibration
/// alone, so nothing of the space timed) and its refit (rank_then_time), one per configuration.
struct RankedInputs {
    std::vector<double> predicted;
    std::function<std::optional<std::vector<double>>(const std::vector<std::size_t>& timed)> refit;
    std::size_t replays =
        0;  ///< configurations replayed to rank them (each once per scene; rays counted, the update timed)
};

/// One tuning problem (a structure's space on a category) compared at one budget.
struct BudgetComparison {
    std::size_t configurations = 0;     ///< in the space
    std::size_t classes = 0;            ///< structures in effect among them
    std::size_t budget = 0;             ///< distinct configurations each method may evaluate
    double optimum_table = 0;           ///< the lowest class cost in the table
    double optimum = 0;                 ///< that class's score (its cost re-measured)
    std::vector<double> tuner_regrets;  ///< search_levels, one per seed: found's score / optimum − 1
    double tuner_regret = 0;            ///< their median
    double random_regret = 0;           ///< expected, exact
    double descent_regret = 0;
    /// The cost model's choice (the lowest predicted configuration) without a timed measurement
    /// beyond the model's calibration: NaN when no prediction was given.
    double model_regret = std::numeric_limits<double>::quiet_NaN();
    std::size_t model_timed = 0;  ///< configurations the model's calibration measured
    /// The ranked method at the budget, everything it timed counted (NaN: no model to rank by),
    /// and without its refit (the micro-scene calibration's ranking alone).
    double ranked_regret = std::numeric_limits<double>::quiet_NaN();
    double ranked_unrefitted_regret = std::numeric_limits<double>::quiet_NaN();
    std::size_t ranked_timed = 0, ranked_replays = 0, ranked_refits = 0;
    /// The tuner as it runs: the ranked method where it has a model, else the search.
    double tuner() const { return std::isnan(ranked_regret) ? tuner_regret : ranked_regret; }
};

/// The comparison on the surface `costs` (one per configuration of `all` = enumerate_space(dims),
/// in its order; ∞ or NaN: unusable) whose configurations fall in classes `class_of` (same order,
/// ids from 0). The budget is ceil(share × classes), at least 1; the tuner runs `seeds` seeds from
/// `first_seed`, all methods from `start`. With `predicted` (same order), the model's choice is
/// priced too; `model_timed` says what its calibration measured. With `ranked`, the ranked method
/// runs at the same budget, its timings read from the surface. Every choice is scored on `scores`
/// (same order: the space measured again); empty: on `costs`, the table chosen from.
BudgetComparison compare_at_equal_budget(const std::vector<SearchDimension>& dims,
                                         const std::vector<nlohmann::json>& all, const std::vector<double>& costs,
                                         const std::vector<std::size_t>& class_of, const nlohmann::json& start,
                                         double share, std::uint64_t first_seed, std::size_t seeds,
                                         const std::vector<double>& predicted = {}, std::size_t model_timed = 0,
                                         const RankedInputs* ranked = nullptr, const std::vector<double>& scores = {});

/// Class ids (from 0, in order of first appearance) of items equal under `same`.
template <class T, class Same>
std::vector<std::size_t> equality_classes(const std::vector<T>& items, Same&& same) {
    std::vector<std::size_t> class_of(items.size());
    std::vector<std::size_t> representative;  // first item of each class
    for (std::size_t i = 0; i < items.size(); ++i) {
        std::size_t c = 0;
        while (c < representative.size() && !same(items[representative[c]], items[i])) ++c;
        if (c == representative.size()) representative.push_back(i);
        class_of[i] = c;
    }
    return class_of;
}

/// Over problems: the median and p90 of each method's regret, and the share of problems where
/// a method's regret is below random's (ties within 1e-9 count as not below) and not above the
/// descent's: the search's (tuner_*, beats_random, matches_descent) and the tuner's as it runs
/// (BudgetComparison::tuner: the ranked method where it has a model).
struct SuiteSummary {
    std::size_t problems = 0;
    double tuner_median = 0, tuner_p90 = 0;
    double random_median = 0, random_p90 = 0;
    double descent_median = 0, descent_p90 = 0;
    double beats_random = 0;         ///< share of problems
    double matches_descent = 0;      ///< share of problems where the tuner is at least as good
    std::size_t model_problems = 0;  ///< problems with a model's choice
    double model_median = std::numeric_limits<double>::quiet_NaN(), model_p90 = model_median;
    double median_budget_share = 0;              ///< budget / classes, median over problems
    std::size_t ranked_problems = 0;             ///< problems the ranked method ran on
    double running_median = 0, running_p90 = 0;  ///< the tuner as it runs
    double running_beats_random = 0, running_matches_descent = 0;
    double median_replays = 0;  ///< the ranked method's replays, median over its problems
};
SuiteSummary summarize_suite(const std::vector<BudgetComparison>& problems);

}  // namespace rcb
