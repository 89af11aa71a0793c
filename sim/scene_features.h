#pragma once
/// Descriptors of a scene, computed from its recording alone, so that scene categories can be
/// derived from the scenes themselves instead of named by hand (the thesis' future work, §7.2).
///
/// Every feature is dimensionless (sizes relative to the scene, counts on a log scale), so a map
/// and a generated scene of another world size compare. Pure and deterministic: the same
/// recording gives the same values, bit for bit (one thread, fixed order, no randomness). Linear
/// in the objects plus a ground-truth pass of at most kFeatureRays rays over the objects.

#include <array>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "core/scene/scene.h"

namespace rcb {

/// The features, in this order (names as stored in the database and the tuning files):
///   log10_objects        log10 of frame 0's object count
///   size_p50             median of log10(box longest edge / scene longest edge)
///   size_spread          p90 − p10 of that: how mixed the sizes are (irregular scenes, §6.1)
///   flatness             log10(shortest / longest edge of the scene bounds), ≥ −6: maps are flat
///   occupancy            occupied cells / min(objects, cells) of the reference lattice (about n
///                        cubic cells over the bounds, object centres binned): 1 for one
///                        object per cell, ≈ 0.63 for independently placed centres, lower
///                        when they cluster
///   log10_count_cv       log10 of the coefficient of variation of centres per lattice cell
///                        (≈ 0 uniform, larger clustered)
///   log10_hits_per_ray   log10(1 + mean must-hit objects per ray), ground truth of frame 0's
///                        first kFeatureRays rays (evenly spaced) after frame 0's changes
///   log10_cells_per_ray  log10(1 + mean cells of the reference lattice a frame-0 ray crosses),
///                        the grid walk of eq. 5.4's N_T for a UG of density 1
///   ray_length           median frame-0 ray length / diagonal of the scene bounds
///   change_rate          mean changes per frame / objects (thesis §5.2.1: 1% by default)
inline constexpr std::size_t kSceneFeatureCount = 10;
inline constexpr std::size_t kFeatureRays = 64;

using FeatureValues = std::array<double, kSceneFeatureCount>;

const std::array<std::string_view, kSceneFeatureCount>& scene_feature_names();

struct SceneFeatures {
    FeatureValues values{};

    nlohmann::json to_json() const;  ///< {"log10_objects": …, …} in the order above
    /// InputError "<where>: …" when a feature is missing or not a finite number.
    static SceneFeatures from_json(const nlohmann::json& j, const std::string& where);
    friend bool operator==(const SceneFeatures&, const SceneFeatures&) = default;
};

SceneFeatures compute_scene_features(const Recording& recording);

}  // namespace rcb
