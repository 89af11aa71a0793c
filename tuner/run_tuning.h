#pragma once
/// A whole tuning as one call: every category of a tuning file searched (tuning.h), the results
/// stored in the database and written as tuning-<name>.md/.json with convergence charts.

#include <functional>
#include <string>
#include <vector>

#include "tuner/tuning.h"

namespace rcb {

struct TuneOptions {
    std::string file;  ///< the tuning file (an input: never overwritten)
    std::string db = "results/rcbench.db";
    std::string out_dir = "results";
    bool exhaustive = false;  ///< also measure every configuration and report the tuner's gap
    std::function<void(const std::string& category)> progress;  ///< called as each category starts
};

struct TuneOutcome {
    std::vector<CategoryTuning> categories;
    std::string md_path, json_path;
};

/// Output paths are checked before the search (InputError when they name an input or an
/// unwritable place).
TuneOutcome run_tuning(const TuneSpec& spec, const TuneOptions& options);

/// The searched parameters of a candidate, "density=4 outlier_guard=true".
std::string searched_parameters(const TuneSpec& spec, const Candidate& candidate);

}  // namespace rcb
