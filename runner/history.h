#pragma once
/// Regression history over many runs, as airspeed velocity (asv) shows it: per experiment, scene
/// and configuration, the median frame time of every run in run order, and the steps where the
/// level changed by more than the runs' noise.
///
/// The history is modelled as asv models a benchmark's (asv's step_detect: "piecewise constant
/// plus random noise"), but the steps are found by moving windows (MOSUM; Eichinger & Kirch 2018,
/// "A MOSUM procedure for the estimation of multiple random change points") with a per-boundary
/// test in place of asv's penalised fit. At each boundary between runs, the frames of the w runs
/// before it are compared with those of the w runs after it (fewer at the ends of the history),
/// for w from 2 to `window`, the strongest w counting; the boundary is a candidate when
///   |median(after) - median(before)| > k × MAD   and   Mann–Whitney U p < alpha (runner/compare.h),
/// where MAD is the larger of the two sides' median absolute deviations (each frame from its own
/// side's median), so it holds the frame-to-frame and the run-to-run spread, and a side that mixes
/// two levels is too noisy to pass. A change is also seen from the boundaries next to it, so every
/// candidate is then re-tested between its final neighbouring segments and the weakest failing one
/// dropped until all pass. So a one-run blip inside the history (a busy machine) is not a level
/// change, a level held by two runs or more is, and a slow last run is a step (nothing after it
/// says otherwise yet).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "runner/sqlite.h"

namespace rcb {

struct StepOptions {
    double k = 3.0;              ///< a step must exceed this many MADs of the frame times
    double alpha = 0.01;         ///< and the U test must reject at this level
    std::size_t window = 3;      ///< runs compared on either side of a boundary
    std::size_t min_frames = 5;  ///< frames each side needs for a test (as rcbench compare)
};

/// A change of level between two neighbouring segments of runs.
struct Step {
    std::size_t at = 0;            ///< index of the first run of the new level
    double before = 0, after = 0;  ///< medians of the frames of the segments before and after
    double change = 0;             ///< after / before - 1: above 0 is slower
    double noise = 0;              ///< the larger MAD of the two segments' frames
    double p_value = 1;            ///< two-sided Mann–Whitney U
};

/// Steps of a series given each run's frame times (in run order), by the method above.
std::vector<Step> detect_steps(const std::vector<std::vector<double>>& runs, const StepOptions& options = {});

struct HistoryQuery {
    std::string experiment;                 ///< empty: every experiment
    std::string scene;                      ///< scene name; empty: every scene
    std::string structure;                  ///< structure name; empty: every structure
    std::string binary;                     ///< only the runs of this program (run.binary); empty: every one
    std::string metric = "raycast";         ///< "raycast" or "update"
    std::optional<std::int64_t> up_to_run;  ///< only runs ordered up to and including this one
    StepOptions steps;
};

/// One run's measurement of one series.
struct HistoryPoint {
    std::int64_t run = 0;
    std::string commit, started_at;
    std::string scene_hash;  ///< the scene content measured (equal hashes: identical scenes)
    std::size_t frames = 0;  ///< frames that are not warm-up, over the run's repetitions
    double median_ns = 0, mad_ns = 0;
};

/// One experiment × scene × configuration over the runs of one program that measured it.
struct HistorySeries {
    std::string experiment, scene, structure, params;
    /// The program whose runs these are (run.binary, runner/binary_identity.h): rcbench's runs and
    /// those of a program linking rcbench::cli are separate series, each with its own steps.
    std::string binary;
    std::vector<HistoryPoint> points;  ///< run order: started_at, then run id
    std::vector<Step> steps;           ///< Step::at indexes `points`
};

/// Reads the series the query selects (each with its steps). InputError for an unknown experiment,
/// an unknown run, or filters that match no measured cell.
std::vector<HistorySeries> load_history(Database& db, const HistoryQuery& query);

/// "b87aa7c2fdd4-dirty" → "b87aa7c-dirty": a hexadecimal commit cut to 7 digits; other text as is.
std::string short_commit(const std::string& commit);

}  // namespace rcb
