#pragma once
/// The run loop: an experiment's plan (or one shard of it) simulated cell by cell into the results
/// database, resuming an unfinished run. The command line and other programs call this one entry
/// point; it prints nothing.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "runner/experiment.h"
#include "runner/store.h"

namespace rcb {

struct RunOptions {
    std::string db = "results/rcbench.db";
    std::size_t shard_k = 1, shard_n = 1;  ///< run every N-th cell from the K-th (1-based)
    bool new_run = false;                  ///< start a new run even when an unfinished one could resume
    std::int64_t run_id = 0;               ///< resume this run (0: the newest unfinished one, or a new one)
    /// Called once when another runner holds the database and this one waits for it to finish
    /// (one runner per database at a time; the waiting one then resumes the run it chose).
    std::function<void()> on_wait;
    /// For tests only (no file or option sets it): replaces each simulated cell's times before it
    /// is stored, so a test of what the runner decides from times (which cells get another
    /// repetition) does not depend on how fast the machine is.
    std::function<void(SimulationResult&)> timing;
    /// Another calibration pass of every structure follows the first cell that ends at least this
    /// long after the last pass (runner/calibration.h add_calibration_pass): a run of minutes is
    /// calibrated several times, minutes apart. Tests set it to 0 (a pass after every cell).
    std::chrono::seconds calibration_spacing{120};
};

/// What a run did: its id, the cells of the (shard's) plan, how many were done before, how many
/// now ran, hits that disagreed with the ground truth, and whether the whole plan is now stored.
struct RunOutcome {
    std::int64_t run = 0;
    std::size_t planned = 0, done_before = 0, ran = 0;
    std::uint64_t mismatches = 0;
    std::size_t slow = 0;          ///< cells of the run flagged as measured on a slow machine (store.h)
    std::size_t resampled = 0;     ///< cells measured after waiting for a slow machine (now)
    std::size_t added = 0;         ///< repetitions added where the interval over the stored ones was wide
    std::size_t calibrations = 0;  ///< calibration passes made now (the first included)
    /// Recordings generated, imported or read now: one per recording_key, shared by its windows.
    std::size_t recordings = 0;
    bool finished = false;
};

/// The machine's state now: the 1-minute load average (/proc/loadavg; -1 when unreadable), the
/// memory probe (memory_probe_ns) and the median time of three passes of a fixed integer loop (about 1 ms each on a 3
/// GHz core). The loop is a dependent multiply-add chain, so it measures the core's speed (frequency, a co-scheduled
/// process) and not memory; timed before each cell to separate the machine's noise from the cost model's error.
MachineState sample_machine_state();
/// The median time of three passes of 100 000 dependent loads along a random cycle through 8 MiB:
/// the latency of the shared caches and memory, which a process on the other core slows though it
/// leaves the integer loop alone (a memory-bound ray batch then slows with it).
double memory_probe_ns();

/// Called before each cell runs: cells run so far, cells to run, and what runs now.
using RunProgress = std::function<void(std::size_t ran, std::size_t todo, const std::string& what)>;

/// The cells of shard K/N of the plan: every N-th from the K-th.
std::vector<Cell> shard_plan(const Experiment& e, std::size_t shard_k, std::size_t shard_n);

/// Short label of a configuration: its structure and the parameters that differ from the defaults.
std::string config_label(const ConfigSpec& c);

/// (max − min) / median of a cell's repetitions; 0 for fewer than two.
double relative_range(const std::vector<double>& values);

/// Whether the 95% interval over all of a cell's repetitions' medians stored so far
/// (core/base/statistics.h) has a half-width above `limit` of their median; always for
/// fewer than two repetitions. It decides where a repetition is added, to sharpen the cell's median;
/// the interval the cell states rests on its planned repetitions alone.
bool wide_interval(const std::vector<double>& medians, double limit);

/// Runs the cells not yet stored, then rounds of repetitions where the interval over the stored
/// ones is wide (Experiment::max_repetitions, repeat_interval); `source` names the experiment in errors. InputError for
/// bad input (a scene that cannot be loaded, warm-up that leaves no frame), naming the scene.
RunOutcome run_experiment(const Experiment& e, const std::string& source, const RunOptions& options,
                          const RunProgress& progress = {});

}  // namespace rcb
