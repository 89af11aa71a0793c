#pragma once
/// What a recording asks of a structure per frame, the two sides of the per-frame cost (thesis
/// §5.2.2: update, then ray cast): how many rays of each query kind, and how much of the scene
/// changes and how far. `scene info` prints it, and `advise` prints it beside its advice, whose
/// measurements and model replays run on exactly these changes and rays.

#include <array>
#include <cstddef>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/scene/scene.h"

namespace rcb {

struct SceneWorkload {
    std::size_t frames = 0;
    std::array<std::size_t, kQueryKinds> rays_by_kind{};  ///< over every frame, by QueryKind
    double rays_per_frame = 0, changes_per_frame = 0;     ///< means over the frames
    std::size_t inserts = 0, removes = 0, moves = 0;      ///< over every frame
    /// Share of the live objects changed (inserted, removed or moved) per frame: p10, p50, p90.
    double changed_p10 = 0, changed_p50 = 0, changed_p90 = 0;
    std::vector<double> first_frames, last_frames;  ///< that share in the first and last three frames
    /// Each move's centre displacement over the object's longest edge before the move (moves of
    /// zero-size objects left out): median, p90 and how many.
    double move_median = 0, move_p90 = 0;
    std::size_t measured_moves = 0;

    std::size_t rays() const { return rays_by_kind[0] + rays_by_kind[1] + rays_by_kind[2]; }
    /// The share of the rays of `kind` (0 without rays).
    double kind_share(QueryKind kind) const;
    /// {"query_kinds": {"all": n, …}, "query_shares": {…}, "rays_per_frame", "changes_per_frame",
    ///  "inserts", "removes", "moves", "motion": {"changed_share": {p10, p50, p90}, "first_frames",
    ///  "last_frames", "move_over_size": {median, p90, moves}}}
    nlohmann::json to_json() const;
    /// "closest 50.0%, any 30.0%, all 20.0%" (kinds with rays, most first; "no rays" without).
    std::string kinds_text() const;
};

SceneWorkload scene_workload(const Recording& r);

}  // namespace rcb
