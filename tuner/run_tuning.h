#pragma once
/// A whole tuning as one call: every category of a tuning file searched (tuning.h), the results
/// stored in the database and written as tuning-<name>.md/.json with convergence charts.

#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
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

/// run_tuning's steps: the output paths checked; the scenes' features and categories
/// (categorize_tuning_scenes); then per category tune_category (tuning.h: calibrate, search,
/// measure, fit, verify), its rows stored, its report section and JSON; with --exhaustive every
/// configuration measured and the search replayed on that surface (replay_search_on_surface);
/// last the report, JSON and convergence charts written.
///
/// Output paths are checked before the search (InputError when they name an input or an
/// unwritable place).
TuneOutcome run_tuning(const TuneSpec& spec, const TuneOptions& options);

/// Features of every scene of the spec and its categories' centroids among them. With `derive`,
/// the distinct scenes of all categories are pooled and spec.categories is replaced by the derived
/// categories (cluster_scenes, seeded by spec.seed), so that tuning runs per derived category.
SceneClustering categorize_tuning_scenes(TuneSpec& spec, bool derive);

/// The search replayed on an exhaustively measured surface, once per seed.
struct SurfaceReplay {
    std::uint64_t seed = 0;
    std::size_t evaluations = 0;  ///< distinct configurations the search evaluated
    double best_ms = 0;           ///< the best it found, on the surface it searched
    nlohmann::json best_params;
    double scored_ms = NAN;  ///< that configuration re-measured (tune --exhaustive's scoring pass)
};

/// search_levels on `surface` (searched parameters' compact JSON → cost) with `seeds` seeds from
/// `first_seed`, each from `start` with `budget`: the search's gap to the optimum apart from the
/// noise of measuring again. std::out_of_range when the surface lacks a configuration of `dims`.
std::vector<SurfaceReplay> replay_search_on_surface(const std::vector<SearchDimension>& dims,
                                                    const std::map<std::string, double>& surface, std::size_t budget,
                                                    std::uint64_t first_seed, std::size_t seeds,
                                                    const nlohmann::json& start);

/// The searched parameters of a candidate, "density=4 outlier_guard=true".
std::string searched_parameters(const TuneSpec& spec, const Candidate& candidate);

}  // namespace rcb
