#pragma once
/// Which structure to ship for a user's scene: every registered structure measured on it at its
/// tuned parameters (from a tuning result's category) or its defaults, fastest first.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "tuner/tuning.h"

namespace rcb {

struct AdviseOptions {
    std::string scene;              ///< a recording, or a boxes CSV (given 10 frames of 1% dynamics, 1000 centre rays)
    std::string tuning, category;   ///< both or neither: a tuning result (tuning-<name>.json) and its category
    std::uint32_t repetitions = 3;  ///< measurements per structure
    std::uint32_t warmup = 1;       ///< frames left out of the medians
    std::function<void(const std::string& structure)> progress;  ///< called as each structure starts
};

struct AdviceRow {
    std::string structure, params;  ///< params as compact JSON
    MeasuredCost cost;
    bool tuned = false;
};

/// Fastest per frame first. InputError for a missing scene, a tuning file that is not a tuning
/// result or lacks the category, or warm-up that leaves no frame.
std::vector<AdviceRow> advise(const AdviseOptions& options);

}  // namespace rcb
