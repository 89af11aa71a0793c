#pragma once
/// Derivative-free search over a structure's parameters with NLopt.
///
/// The space is finite and ordered: each parameter has a list of levels (integers, log- or
/// linearly-spaced reals, choices). NLopt works on the level index of each parameter as a
/// continuous coordinate in [0, levels − 1]; the objective rounds every coordinate to its nearest
/// level before evaluating, so every evaluated point is a real configuration (integers are never
/// "continuous and rounded at the end"), and evaluations are memoised, so the budget counts distinct
/// configurations.
///
/// Algorithm: a budget far below the space (a tenth of it, say) buys a few dozen measurements, so
/// the search goes local first: a coordinate pattern search on the level lattice (neighbouring
/// levels, one dimension at a time) from the start point, the defaults, which the structures'
/// authors chose to be good. Each sweep takes the dimensions that have changed the cost most
/// first (unprobed ones before all: the first sweep in the space's order, which a tuning takes
/// from the structure's parameter list, main parameters first; later ones in a seeded order). It
/// tries a dimension first in the direction that last improved it, else towards the middle of its
/// levels, and while sweeps improve, not back the way it came. Grid parameters give smooth valleys
/// (thesis §6.2: cost falls, then rises, with cell size and depth), so this reaches the valley
/// floor in a few steps. With budget left, NLopt's GN_DIRECT_L_RAND (Gablonsky & Kelley's
/// locally-biased DIRECT with randomised tie-breaking, seeded) looks at the whole box with half of
/// what remains, and the pattern search restarts from the best point found; until the budget is
/// spent or neither finds a new point. A space no larger than the budget is simply enumerated.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace rcb {

struct SearchDimension {
    std::string name;
    std::vector<nlohmann::json> levels;  ///< ordered (simplest or smallest first)
};

struct Evaluation {
    nlohmann::json params;  ///< the searched parameters at their levels
    double cost = 0;
};

struct SearchResult {
    std::vector<Evaluation> evaluations;  ///< distinct configurations, in the order evaluated
    std::size_t best = 0;                 ///< index into evaluations
    std::string algorithm;
    std::string stop_reason;            ///< "budget", "converged", "enumerated", or NLopt's failure
    std::vector<std::string> on_bound;  ///< parameters whose best level is the first or last of its list
    std::size_t space_size = 0;         ///< configurations in the space
};

/// `objective(params)` returns the cost to minimise (NaN or ∞ counts as failed and is avoided).
/// `start` (searched parameters at their levels; a missing or unknown level: the middle one) is
/// evaluated first and counts against the budget.
SearchResult search_levels(const std::vector<SearchDimension>& dims,
                           const std::function<double(const nlohmann::json&)>& objective, std::size_t budget,
                           std::uint64_t seed, const nlohmann::json& start = nlohmann::json());

/// Every configuration of the space (for exhaustive comparisons).
std::vector<nlohmann::json> enumerate_space(const std::vector<SearchDimension>& dims);

/// The tuner's measured method where a cost model exists: rank, then time the best-ranked.
///
/// A budget of a tenth of the space buys too few measurements for a search to find its way
/// (the pattern search above walks from the defaults one level at a time), but a counting replay
/// of every configuration costs no timed ray, and eq. 5.4's coefficients price the replays well
/// enough to rank them (thesis §5.3; docs/model.md as of commit f3b2207, "Ranked, then timed"). So: configurations in
/// one class of `class_of` (one structure in effect: equal counts) are ranked as one, by the
/// median of their members' `predicted` costs (NaN ranks last); the best-ranked class not timed
/// yet has its first member timed, `budget` times or until every class is timed; the fastest
/// measured is kept. After each timing `refit` (when given) may return new predictions from what
/// has been timed so far (a fit of the timed frames), and the ranking of the classes left follows
/// them. Never more than `budget` calls of `time`.
struct RankedResult {
    std::vector<std::size_t> timed;            ///< indices of the timed configurations, in order
    std::vector<double> costs;                 ///< their measured costs (NaN or ∞: failed)
    std::vector<double> predicted_when_timed;  ///< each one's prediction when it was chosen
    std::size_t best = 0;                      ///< index into timed: the lowest measured cost
    std::size_t refits = 0;                    ///< timings after which the ranking changed models
};
RankedResult rank_then_time(
    const std::vector<std::size_t>& class_of, std::vector<double> predicted, std::size_t budget,
    const std::function<double(std::size_t)>& time,
    const std::function<std::optional<std::vector<double>>(const std::vector<std::size_t>& timed)>& refit = {});

}  // namespace rcb
