#pragma once
/// The noise floor of a run: how well the machine repeats the same measurement, to set beside the
/// cost model's held-out error (thesis §5.1 fits eq. 5.4 to measured times; an error no larger
/// than the machine's own scatter cannot be blamed on the model).
///
/// Repeatability of a structure: for every cell (scene × configuration) measured in two or more
/// repetitions, the spread of its repetitions' medians, (max − min) / median: for two repetitions
/// the relative difference of two independent measurements of the cell, as two runs of one
/// experiment would be compared. The repetitions of a cell run at different times of the run, in
/// different orders, each on a freshly built structure (runner/experiment.h). Its median and 90th
/// percentile over the cells are the structure's noise. Only the first two repetitions count: the
/// runner adds more where those disagree, and the spread of those would measure the selection.

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "analysis/repetitions.h"
#include "core/base/statistics.h"
#include "runner/results_reader.h"

namespace rcb {

/// One repetition of one cell.
struct RepeatSample {
    std::string structure;
    std::string cell;                      ///< identifies scene × configuration
    double raycast_ns = 0, update_ns = 0;  ///< per frame (the cell's median over frames)
    bool slow = false;                     ///< measured while the calibration loop ran slow
    std::int64_t repetition = 0;
};

struct StructureNoise {
    std::string structure;
    std::size_t cells = 0;        ///< cells with at least two repetitions
    std::size_t repetitions = 0;  ///< repetitions of those cells
    double raycast = NAN;         ///< median over cells of the repetitions' spread of ray-cast time per frame
    double raycast_p90 = NAN;     ///< its 90th percentile
    double update = NAN;          ///< the same of update time per frame (NaN when no update time)
    double update_p90 = NAN;
    /// The same of update + ray-cast time per frame: the time the model's frame error is judged on.
    double frame = NAN, frame_p90 = NAN;
    std::size_t slow = 0;  ///< repetitions (of any cell) flagged slow
};

/// Per structure, in name order; a structure with no repeated cell has NaN deviations.
std::vector<StructureNoise> repeatability(const std::vector<RepeatSample>& samples);

struct NoiseFloor {
    std::vector<StructureNoise> structures;
    std::size_t cells = 0, slow = 0;     ///< stored cells, and those flagged slow
    std::size_t with_state = 0;          ///< cells with a recorded machine state
    double load_median = NAN;            ///< median 1-minute load average over the cells
    double calibration_median_ns = NAN;  ///< median calibration-loop time
    /// The structure's entry, or nullptr.
    const StructureNoise* find(const std::string& structure) const;
};

/// The noise floor of run `run` (with its sibling shards, as the fit sees them). A database from
/// before the machine state was recorded gives repeatability only.
NoiseFloor noise_floor(Database& db, std::int64_t run);

/// How far two independent runs of one experiment (two processes, at two times) measure the same
/// cell, per structure: for every scene (by content) and configuration both runs hold, the
/// relative range of the two runs' figures of the cell (`how`, analysis/repetitions.h); median and
/// 90th percentile over those cells, for the frame (update + ray cast), ray cast and update. This, not the repetitions
/// of one run, is the floor a model's error is judged against: a model cannot be told apart from a rerun below it.
/// `cells` counts the cells both runs hold; `slow` those with a repetition flagged slow in either.
std::vector<StructureNoise> between_runs(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                         OverRepetitions how = OverRepetitions::median);
/// The same over every cell of every structure, as one entry (structure "all").
StructureNoise between_runs_pooled(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                   OverRepetitions how = OverRepetitions::median);

/// The update between two runs, by its size. A small update's time is mostly the state its
/// structure's lines are in when it starts (which the other core and the host's other tenants
/// set, differently in two runs: docs/model.md as of commit f3b2207, "Where the update's spread lives"), a large one's
/// the work; one p90 over every cell hides which figures repeat. A cell's size is the geometric
/// mean of the two runs' update per frame; `share` says how much of the frame the band's updates are.
struct UpdateBand {
    double from_ns = 0, below_ns = INFINITY;  ///< the band: from_ns <= size < below_ns
    std::size_t cells = 0;                    ///< cells both runs hold with an update in the band
    double update = NAN, update_p90 = NAN;    ///< relative range of the two runs' update: median, p90
    double share = NAN;                       ///< median over the cells of update / (update + ray cast)
};
/// The bands under 10 us, 10-30, 30-100 and from 100 us, in that order (every band, empty ones too),
/// over every cell of every structure both runs hold, each run's figure of a cell by `how`.
std::vector<UpdateBand> between_runs_by_update(Database& a, std::int64_t run_a, Database& b, std::int64_t run_b,
                                               OverRepetitions how = OverRepetitions::fastest_cast);

/// A cell measured while the machine was slow.
struct SlowCell {
    std::string scene, structure, params;
    std::int64_t repetition = 0;
    double load_1m = 0;
    double calibration_ratio = 0;  ///< its calibration time over the run's median
};
/// The run's (and its sibling shards') cells flagged slow, in the order measured.
std::vector<SlowCell> slow_cells(Database& db, std::int64_t run);

/// "2.3%", or "-" when there is no repeated cell.
std::string noise_text(double deviation);
/// "2.3% / 7.9%" (median / p90), or "-".
std::string noise_text(double p50, double p90);

}  // namespace rcb
