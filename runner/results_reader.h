#pragma once
/// The results database's one reader: every query analysis/ and cli/ make of a stored run, as
/// typed rows. Callers pass a run id (and, where a query needs them, the columns or names to read)
/// and get structs back; the SQL, the run group of shards (kRunGroupSql) and the scene labels
/// (kSceneLabelSql) stay here, beside the store that writes the tables (runner/store.h, schema in
/// docs/database.md). As google/benchmark's compare.py loads before report.py computes, the readers
/// only load: medians, orders over repetitions and everything computed stay with the caller.
///
/// "Of run R" below means of R and its sibling shards (kRunGroupSql), as every analysis reads a
/// run. A NULL number reads as 0 unless the row says otherwise.

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace rcb {

class Database;

// ---------------------------------------------------------------------------------------------
// Runs

/// The provenance of one run (the run and experiment tables).
struct StoredRun {
    std::string experiment, uuid, started_at, git_commit, cpu_model, compiler;
    std::int64_t cores = 0;
    std::string binary, binary_id;  ///< the program that made it (runner/binary_identity.h)
};

/// Run `run`'s provenance; nullopt when there is no such run.
std::optional<StoredRun> read_stored_run(Database& db, std::int64_t run);

bool run_exists(Database& db, std::int64_t run);

/// The newest run with measured cells, of experiment `experiment` (any experiment when empty).
std::optional<std::int64_t> latest_measured_run(Database& db, const std::string& experiment);

/// The experiment file's content as the run stored it; nullopt when there is no such run.
std::optional<std::string> read_experiment_content(Database& db, std::int64_t run);

// ---------------------------------------------------------------------------------------------
// Cells: one row per stored cell (scene × configuration × repetition) of run R, in cell order.

/// A cell with its configuration and its frames' sums (the report's rows).
struct CellTotalsRow {
    std::int64_t id = 0;
    std::string scene, spec, structure, params;  ///< scene: its label (kSceneLabelSql)
    double objects = 0, build_ns = 0, update_ns = 0, raycast_ns = 0, memory_bytes = 0;
    std::int64_t repetition = 0;
    /// Sums over the cell's frames: hits, returned, correct and relevant over measured frames only,
    /// missed, extra and duplicate over every frame.
    double hits = 0, missed = 0, extra = 0, duplicate = 0, returned = 0, correct = 0, relevant = 0;
    bool verified = false;
};
std::vector<CellTotalsRow> read_cell_totals(Database& db, std::int64_t run);

/// A cell's configuration with its counts per ray over its measured frames (the findings' rows).
struct CellCountsRow {
    std::string scene, spec, structure, params;
    std::int64_t objects = 0, scene_id = 0, config_id = 0, memory_bytes = 0;
    double n_t = 0, n_rb = 0, n_tp = 0;  ///< sum over measured frames / max(sum of rays, 1)
};
std::vector<CellCountsRow> read_cell_counts(Database& db, std::int64_t run);

/// A cell's medians and its machine state (cell_state; absent for runs stored before it).
struct CellStateRow {
    std::string structure;
    std::int64_t scene_id = 0, config_id = 0, repetition = 0;
    double raycast_ns_median = 0, update_ns_median = 0;
    bool has_state = false;  ///< the cell has a cell_state row; the three below read 0 without one
    bool slow = false;
    double load_1m = 0, calibration_ns = 0;
};
std::vector<CellStateRow> read_cell_states(Database& db, std::int64_t run);

/// A cell's keys across databases: the scene's content hash and the configuration's parameters.
struct CellIdentityRow {
    std::int64_t scene_id = 0, config_id = 0;
    std::string structure, scene_hash, params;
    bool slow = false;  ///< flagged slow in cell_state (false without a row)
};
std::vector<CellIdentityRow> read_cell_identities(Database& db, std::int64_t run);

/// A cell's stored medians over its frames.
struct CellMediansRow {
    std::int64_t scene_id = 0, config_id = 0;
    double raycast_ns_median = 0, update_ns_median = 0;
};
std::vector<CellMediansRow> read_cell_medians(Database& db, std::int64_t run);

/// A cell flagged slow, with its machine state.
struct SlowCellRow {
    std::string scene, structure, params;
    std::int64_t repetition = 0, run_id = 0;
    double load_1m = 0, calibration_ns = 0;
};
std::vector<SlowCellRow> read_slow_cells(Database& db, std::int64_t run);

/// Every calibration-loop time of run R's cells (those with a cell_state row), with the cell's run.
struct CellCalibrationRow {
    std::int64_t run_id = 0;
    double calibration_ns = 0;
};
std::vector<CellCalibrationRow> read_cell_calibrations(Database& db, std::int64_t run);

// ---------------------------------------------------------------------------------------------
// Frames

/// Repetition-0 series of one cell, in frame order.
struct FrameSeriesRow {
    double raycast_ns = 0;
    double sah_cost = 0;  ///< NaN when not recorded
};
std::vector<FrameSeriesRow> read_frame_series(Database& db, std::int64_t cell);

/// One measured frame (warm-up left out) of a cell of run R, keyed by (scene, configuration, frame)
/// and so the same frame over the cell's repetitions.
struct FrameTimeRow {
    std::int64_t scene_id = 0, config_id = 0, frame = 0;
    double raycast_ns = 0, update_ns = 0;
};
/// Every measured frame of every repetition.
std::vector<FrameTimeRow> read_frame_times(Database& db, std::int64_t run);
/// One row per (scene, configuration, frame): its fastest ray-cast and update time over the repetitions.
std::vector<FrameTimeRow> read_fastest_frame_times(Database& db, std::int64_t run);

/// A measured frame with its configuration and the counter columns the caller asked for.
struct FrameCountersRow {
    std::string structure, params;
    std::int64_t scene_id = 0, config_id = 0, frame = 0;
    double rays = 0, raycast_ns = 0, update_ns = 0;
    std::vector<double> counters;  ///< in the order of the columns asked for; NaN where NULL (not recorded)
};
/// The measured frames of run R with `columns` (e.g. "frame.n_rb", "cell.objects"): every frame
/// of every repetition in cell and frame order, or with `fastest` one row per frame of a (scene,
/// configuration), the smallest value of each figure and counter over its repetitions, in the order
/// of their first cell.
std::vector<FrameCountersRow> read_frame_counters(Database& db, std::int64_t run, bool fastest,
                                                  const std::vector<std::string>& columns);

/// The (cell, frame) of every measured frame of run R, in cell and frame order.
std::vector<std::pair<std::int64_t, std::int64_t>> read_measured_frame_keys(Database& db, std::int64_t run);

/// A frame's batch of one query kind (frame_kind) with its counters in kCounterFields order.
struct FrameKindRow {
    std::int64_t cell_id = 0, frame = 0;
    std::string kind;
    double rays = 0, raycast_ns = 0;
    std::vector<double> counters;
};
/// The frame_kind rows of run R's measured frames.
std::vector<FrameKindRow> read_frame_kinds(Database& db, std::int64_t run);
/// Whether any cell of run R recorded query kinds.
bool run_has_frame_kinds(Database& db, std::int64_t run);

/// Objects changed in one frame (inserted, removed or moved) of the first cell of each scene of run R
/// (every cell of a scene replays the same frames), in cell and frame order.
struct FrameChangesRow {
    std::string scene;  ///< its label
    double objects = 0, changes = 0;
};
std::vector<FrameChangesRow> read_scene_changes(Database& db, std::int64_t run);

// ---------------------------------------------------------------------------------------------
// Scenes, calibration, fits

/// A scene measured in run R, in scene id order.
struct RunSceneRow {
    std::int64_t id = 0;
    std::string label, spec;
};
std::vector<RunSceneRow> read_run_scenes(Database& db, std::int64_t run);

/// A scene's label and its spec; nullopt for no such scene.
std::optional<std::pair<std::string, std::string>> read_scene_label(Database& db, std::int64_t scene_id);

/// The structures with calibration points stored for run `run` (that run only), in name order.
std::vector<std::string> read_calibrated_structures(Database& db, std::int64_t run);

/// Per structure, coefficient `coefficient` of the fits of run `run` (that run only) of `target`
/// and `model` that converged (status 'ok').
std::map<std::string, double> read_fit_coefficients(Database& db, std::int64_t run, const std::string& target,
                                                    const std::string& model, const std::string& coefficient);

}  // namespace rcb
