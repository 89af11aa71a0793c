#pragma once
/// Which structure to ship for a user's scene: every registered structure measured on it at its
/// tuned parameters (from a tuning result's category) or its defaults, fastest first. Without a
/// category the scene's features pick the tuning's nearest category (analysis/scene_categories.h).

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

struct Advice {
    std::vector<AdviceRow> rows;             ///< fastest per frame first
    std::optional<std::size_t> recommended;  ///< the fastest row that meets the accuracy; none when none does
    std::optional<CategoryChoice> chosen;    ///< when the category came from the scene's features
};

/// InputError for a missing scene, --category without --tuning, a tuning file that is not a
/// tuning result or lacks the category (or, with no category, lacks scene categories: written by
/// an older rcbench), or warm-up that leaves no frame.
Advice advise(const AdviseOptions& options);

/// Sorts `rows` fastest first, marks which meet `accuracy`, and returns the fastest that does.
std::optional<std::size_t> rank_advice(std::vector<AdviceRow>& rows, const AccuracyConstraint& accuracy);

/// The category of `tuning` (a tuning result file) nearest the scene's features.
CategoryChoice choose_category(const std::string& tuning, const nlohmann::json& tuning_json, const Recording& scene);

}  // namespace rcb
