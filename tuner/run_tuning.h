#pragma once
/// A whole tuning as one call: every category of a tuning file searched (tuning.h), the results
/// stored in the database and written as tuning-<name>.md/.json with convergence charts.

#include <functional>
#include <string>
#include <vector>

#include "analysis/scene_categories.h"
#include "tuner/tuning.h"

namespace rcb {

struct TuneOptions {
    std::string file;  ///< the tuning file (an input: never overwritten)
    std::string db = "results/rcbench.db";
    std::string out_dir = "results";
    bool exhaustive = false;  ///< also measure every configuration and report the tuner's gap
    /// Pool the file's scenes and tune per category derived from their features
    /// (analysis/scene_categories.h) instead of per category the file names.
    bool derive_categories = false;
    std::function<void(const std::string& category)> progress;  ///< called as each category starts
};

struct TuneOutcome {
    std::vector<CategoryTuning> categories;
    SceneClustering scene_categories;  ///< the categories' centroids in feature space (derived or as named)
    std::string md_path, json_path;
};

/// Output paths are checked before the search (InputError when they name an input or an
/// unwritable place).
TuneOutcome run_tuning(const TuneSpec& spec, const TuneOptions& options);

/// Features of every scene of the spec and its categories' centroids among them. With `derive`,
/// the distinct scenes of all categories are pooled and spec.categories is replaced by the derived
/// categories (cluster_scenes, seeded by spec.seed), so that tuning runs per derived category.
SceneClustering categorize_tuning_scenes(TuneSpec& spec, bool derive);

/// The searched parameters of a candidate, "density=4 outlier_guard=true".
std::string searched_parameters(const TuneSpec& spec, const Candidate& candidate);

}  // namespace rcb
