#pragma once
/// Comparing two runs, like Google Benchmark's compare.py: per scene × configuration, the ratio of
/// median per-frame times, a two-sided Mann–Whitney U test on the per-frame times, and a verdict.

#include <cstdint>
#include <string>
#include <vector>

#include "runner/sqlite.h"

namespace rcb {

/// Two-sided p-value of the Mann–Whitney U test (normal approximation with tie and continuity
/// corrections; Mann & Whitney 1947). NaN when either sample is empty.
double mann_whitney_p(const std::vector<double>& a, const std::vector<double>& b);

struct Comparison {
    std::string scene, structure, params, metric;
    std::size_t baseline_n = 0, candidate_n = 0;
    double baseline_median = 0, candidate_median = 0;
    double ratio = 0;  ///< candidate / baseline median: above 1 is slower
    double p_value = 0;
    std::string verdict;  ///< "faster", "slower", "same", or "too few frames"
    /// Cells (repetitions) of each side measured while the machine was slow (cell_state.slow):
    /// a verdict resting on them may be the machine's, not the code's.
    std::size_t baseline_slow = 0, candidate_slow = 0;
};

/// Runs are selected by id ("12") or by git commit prefix ("3fa9c1"); a commit selects every run
/// made from it (e.g. the shards of one job). `metric` is "raycast", "update" or "both".
std::vector<Comparison> compare_runs(Database& db, const std::string& baseline, const std::string& candidate,
                                     const std::string& metric, double alpha);

/// Run ids a selector names; InputError when none.
std::vector<std::int64_t> select_runs(Database& db, const std::string& selector);

/// The programs that made the runs a selector names (run.binary, runner/binary_identity.h),
/// distinct, in run order: compare says when its two sides come from different programs.
std::vector<std::string> run_binaries(Database& db, const std::string& selector);

}  // namespace rcb
