#pragma once
/// Scene categories derived from the scenes themselves (the thesis' future work, §7.2): the
/// features of sim/scene_features.h, standardised over the scenes at hand (z-scores, with each
/// standard deviation floored at the feature's "noticeable difference", so noise between seeds of
/// one generator is not magnified), grouped by k-means with seeded k-means++ starts. k is the one
/// with the highest mean silhouette over k = 2 … min(8, scenes − 1) among those whose centroids
/// all differ pairwise by at least two noticeable differences in some feature; k = 1 when none
/// reaches a silhouette of 0.25 (Kaufman & Rousseeuw's "no substantial structure"). Each category is named after the
/// fixed category most of its scenes carry
/// ("uniform", "irregular", "import", "recording") plus the feature with the largest |z| of its
/// centroid and a second one if its |z| ≥ 0.5, e.g. "uniform-small-boxes-many-objects" (no
/// feature when k = 1).
///
/// An unseen scene maps to the category whose centroid is nearest in the same standardised space;
/// the match says which features decided it.

#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "sim/scene_features.h"
#include "runner/results_reader.h"

namespace rcb {

/// z = (x − mean) / sd per feature (sd floored, see above).
struct FeatureScaling {
    FeatureValues mean{}, sd{};
    FeatureValues standardize(const FeatureValues& x) const;
};

struct DerivedCategory {
    std::string name;
    std::string nearest_fixed;         ///< the fixed category most of its scenes carry ("" if none known)
    std::vector<std::size_t> members;  ///< indices of the clustered scenes
    FeatureValues centroid{}, z{};     ///< mean features of the members, raw and standardised
};

struct SceneClustering {
    std::uint64_t seed = 1;
    double silhouette = NAN;  ///< mean silhouette of the chosen k; NaN when k = 1 or the groups were given
    std::string rule;         ///< how the categories were made, for reports
    FeatureScaling scaling;
    std::vector<DerivedCategory> categories;
    std::vector<std::size_t> assignment;  ///< per scene, its category

    nlohmann::json to_json() const;
    /// InputError "<where>: …" on a malformed block.
    static SceneClustering from_json(const nlohmann::json& j, const std::string& where);
};

/// Derives categories from `scenes` (fixed: each scene's fixed category, or empty strings).
/// Deterministic for a seed. InputError when there are no scenes.
SceneClustering cluster_scenes(const std::vector<SceneFeatures>& scenes, const std::vector<std::string>& fixed,
                               std::uint64_t seed, std::size_t max_k = 8);

/// Categories given by name (a tuning file's): their centroids in the space of all their scenes,
/// so that an unseen scene can be matched to them as to derived ones.
SceneClustering group_scenes(const std::vector<SceneFeatures>& scenes, const std::vector<std::string>& names,
                             const std::vector<std::vector<std::size_t>>& members);

struct FeatureDeviation {
    std::size_t feature = 0;
    double scene = 0, centroid = 0;  ///< raw values
    double z_scene = 0, z_centroid = 0;
};

struct CategoryMatch {
    std::size_t category = 0;
    double distance = 0;                   ///< Euclidean, standardised units
    std::optional<std::size_t> runner_up;  ///< the next nearest category
    double runner_up_distance = NAN;
    std::vector<FeatureDeviation> defining;  ///< the category's most distinctive features (largest |z| of its centroid)
    std::optional<FeatureDeviation> largest_gap;  ///< where the scene differs most from the centroid
};

/// The nearest category (InputError for a clustering without categories).
CategoryMatch nearest_category(const SceneClustering& clustering, const SceneFeatures& scene);
/// One paragraph: which category, how near, the runner-up, and the scene's features against the centroid.
std::string explain_match(const SceneClustering& clustering, const CategoryMatch& match);

/// A run's derived categories (tables scene_clustering, derived_category, derived_category_scene).
struct RunCategories {
    std::int64_t run = 0;
    std::vector<std::int64_t> scene_ids;
    std::vector<std::string> scene_names;
    SceneClustering clustering;
};

/// Clusters the scenes of run `run` (with its sibling shards) from their stored features.
/// InputError when the run has no scenes or a scene has no stored features (stored by an older
/// rcbench: re-run it).
RunCategories derive_run_categories(Database& db, std::int64_t run, std::uint64_t seed, std::size_t max_k = 8);
/// Replaces the run's stored derived categories.
void store_run_categories(Database& db, const RunCategories& categories);

}  // namespace rcb
