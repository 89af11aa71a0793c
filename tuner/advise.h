#pragma once
/// Which structure to ship for a user's scene: every registered structure measured on it at its
/// tuned parameters (from a tuning result's category) or its defaults, fastest first. Without a
/// category the scene's features pick the tuning's nearest category (analysis/scene_categories.h).
///
/// A tuned structure's parameters for this scene come from one of two methods:
///   category  the category's tuned parameters as they are: the best for the category's scenes
///             on average, which an unseen scene of the same kind need not share (a map's best
///             grid density depends on where its walls fall on the lattice)
///   model     the category's cost model (eq. 5.4, fitted while tuning) applied to this scene's own
///             counters: counting replays of the tuning's space on the scene (its search, with the
///             tuning's budget and seed, from the category's parameters), ranked by predicted cost;
///             the `verify_top` best (one per structure in effect: equal counts are one structure)
///             are measured beside the category's parameters; from the fastest of them a measured
///             descent (one level of one parameter at a time, two where one finds nothing; at
///             most `refine` measurements)
///             corrects the model's misranked neighbours, and the fastest measured is advised
///             (verify_top 0: the predicted best alone)
/// `auto` takes the model where the tuning holds one for the structure, else the category.

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "analysis/scene_categories.h"
#include "tuner/tuning.h"

namespace rcb {

struct AdviseOptions {
    std::string scene;              ///< a recording, or a boxes CSV (given 10 frames of 1% dynamics, 1000 centre rays)
    std::string tuning;             ///< a tuning result (tuning-<name>.json), or empty: defaults
    std::string category;           ///< its category; empty: the one nearest the scene's features
    std::string method = "auto";    ///< how tuned parameters are chosen: auto, category, model
    std::uint32_t verify_top = 3;   ///< model method: its best configurations measured beside the category's
    std::uint32_t refine = 6;       ///< model method: measurements of the descent from the fastest verified
    bool exhaustive = false;        ///< also measure every configuration of each tuned structure's space
    std::uint32_t repetitions = 3;  ///< measurements per structure
    std::uint32_t warmup = 1;       ///< frames left out of the medians
    /// What the recommendation must answer; one that allows inexact answers also measures every
    /// structure at the other query levels (candidates, shapes) and verifies every measurement.
    AccuracyConstraint accuracy;
    std::function<void(const std::string& structure)> progress;  ///< called as each structure starts
};

struct AdviceRow {
    std::string structure, params;  ///< params as compact JSON
    MeasuredCost cost;
    bool tuned = false;
    bool meets = true;  ///< meets the accuracy constraint
};

/// Which of a tuning's categories a scene resembles, and why.
struct CategoryChoice {
    std::string category;
    SceneFeatures features;  ///< the scene's
    CategoryMatch match;
    std::string explanation;  ///< explain_match's paragraph
};

/// One configuration the model method considered: predicted on the scene, measured if verified.
struct ModelCandidate {
    nlohmann::json searched;  ///< the searched parameters
    std::optional<double> predicted_ms;
    std::optional<MeasuredCost> measured;
    bool is_category = false;  ///< the category's tuned parameters
};

/// How a tuned structure's parameters were chosen for the scene, and why.
struct ParameterChoice {
    std::string structure;
    std::string method;                       ///< "category" or "model"
    std::string why;                          ///< one sentence: why this method
    nlohmann::json category_searched;         ///< the category's tuned values of the searched parameters
    nlohmann::json chosen_searched;           ///< what was advised
    std::vector<SearchDimension> space;       ///< the tuning's space (empty: an older tuning without one)
    std::string model;                        ///< the cost model applied (model method)
    std::size_t replays = 0, space_size = 0;  ///< counting replays of the scene (model method) and the space
    std::size_t refined = 0;                  ///< configurations the measured descent added (model method)
    std::vector<ModelCandidate>
        candidates;       ///< model method: measured ones first, fastest first; then the rest by prediction
    std::string summary;  ///< one paragraph for the terminal
};

/// Every configuration of a tuned structure's space measured on the scene: where the advice stands.
struct ExhaustiveAdvice {
    std::string structure;
    std::size_t configurations = 0;
    nlohmann::json best_searched, advised_searched, category_searched;
    double best_ms = 0, advised_ms = 0, category_ms = 0;  ///< from the same measurements
    double advised_gap() const { return advised_ms / best_ms - 1; }
    double category_gap() const { return category_ms / best_ms - 1; }
};

struct Advice {
    std::vector<AdviceRow> rows;               ///< fastest per frame first
    std::optional<std::size_t> recommended;    ///< the fastest row that meets the accuracy; none when none does
    std::optional<CategoryChoice> chosen;      ///< when the category came from the scene's features
    std::vector<ParameterChoice> parameters;   ///< per tuned structure, in registry order
    std::vector<ExhaustiveAdvice> exhaustive;  ///< with AdviseOptions::exhaustive, per tuned structure with a space
};

/// InputError for a missing scene, a method other than auto, category or model, --category or
/// --exhaustive without --tuning, a tuning file that is not a
/// tuning result or lacks the category (or, with no category, lacks scene categories: written by
/// an older rcbench), --method model where the tuning holds no cost model for a structure,
/// --exhaustive with a tuning that records no search space, or warm-up that leaves no frame.
Advice advise(const AdviseOptions& options);

/// Sorts `rows` fastest first, marks which meet `accuracy`, and returns the fastest that does.
std::optional<std::size_t> rank_advice(std::vector<AdviceRow>& rows, const AccuracyConstraint& accuracy);

/// The category of `tuning` (a tuning result file) nearest the scene's features.
CategoryChoice choose_category(const std::string& tuning, const nlohmann::json& tuning_json, const Recording& scene);

/// "density=4 max_depth=2": searched parameters as advise prints them (strings unquoted).
std::string searched_text(const nlohmann::json& searched);

/// The advice as one JSON object (advise --json): the category choice, the parameter choices,
/// the rows, the recommendation and the exhaustive check.
nlohmann::json advice_json(const Advice& advice, const AdviseOptions& options);

}  // namespace rcb
