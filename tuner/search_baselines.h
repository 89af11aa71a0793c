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
/// Configurations that are one structure in effect (equal counts in a counting replay: a hash
/// grid of depth 0 ignores its capacity) are merged first: a class's cost is the median of its
/// members' measurements, the budget is a share of the classes, and random search draws classes.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include <nlohmann/json.hpp>

#include "tuner/search.h"

namespace rcb {

/// The expected lowest of `k` of `costs` drawn uniformly without replacement:
/// Σ_i c_(i) · C(n − i, k − 1) / C(n, k) over the costs in ascending order (i from 1). k is
/// clamped to [1, n]; NaN for no costs.
double expected_best_of_random(std::vector<double> costs, std::size_t k);

/// One tuning problem (a structure's space on a category) compared at one budget.
struct BudgetComparison {
    std::size_t configurations = 0;     ///< in the space
    std::size_t classes = 0;            ///< structures in effect among them
    std::size_t budget = 0;             ///< distinct configurations each method may evaluate
    double optimum = 0;                 ///< the lowest class cost
    std::vector<double> tuner_regrets;  ///< search_levels, one per seed: found / optimum − 1
    double tuner_regret = 0;            ///< their median
    double random_regret = 0;           ///< expected, exact
    double descent_regret = 0;
    /// The cost model's choice (the lowest predicted configuration) without a timed measurement
    /// beyond the model's calibration: NaN when no prediction was given.
    double model_regret = std::numeric_limits<double>::quiet_NaN();
    std::size_t model_timed = 0;  ///< configurations the model's calibration measured
};

/// The comparison on the surface `costs` (one per configuration of `all` = enumerate_space(dims),
/// in its order; ∞ or NaN: unusable) whose configurations fall in classes `class_of` (same order,
/// ids from 0). The budget is ceil(share × classes), at least 1; the tuner runs `seeds` seeds from
/// `first_seed`, all methods from `start`. With `predicted` (same order), the model's choice is
/// priced too; `model_timed` says what its calibration measured.
BudgetComparison compare_at_equal_budget(const std::vector<SearchDimension>& dims,
                                         const std::vector<nlohmann::json>& all, const std::vector<double>& costs,
                                         const std::vector<std::size_t>& class_of, const nlohmann::json& start,
                                         double share, std::uint64_t first_seed, std::size_t seeds,
                                         const std::vector<double>& predicted = {}, std::size_t model_timed = 0);

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
/// the tuner's regret is below random's (ties within 1e-9 count as not below) and not above the
/// descent's.
struct SuiteSummary {
    std::size_t problems = 0;
    double tuner_median = 0, tuner_p90 = 0;
    double random_median = 0, random_p90 = 0;
    double descent_median = 0, descent_p90 = 0;
    double beats_random = 0;         ///< share of problems
    double matches_descent = 0;      ///< share of problems where the tuner is at least as good
    std::size_t model_problems = 0;  ///< problems with a model's choice
    double model_median = std::numeric_limits<double>::quiet_NaN(), model_p90 = model_median;
    double median_budget_share = 0;  ///< budget / classes, median over problems
};
SuiteSummary summarize_suite(const std::vector<BudgetComparison>& problems);

}  // namespace rcb
