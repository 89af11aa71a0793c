#pragma once
/// The results database: the contract between rcbench's stages (schema: docs/database.md).
///
/// Versioned with `PRAGMA user_version` and forward-only migrations: an older database is migrated
/// when opened for writing; a newer one is refused. Each cell is stored in one transaction, so a
/// killed runner loses at most the cell in flight.

#include <cmath>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "core/base/statistics.h"
#include "sim/scene_features.h"
#include "sim/simulator.h"
#include "runner/experiment.h"
#include "runner/sqlite.h"

namespace rcb {

/// The schema version this rcbench writes.
int latest_schema_version();

/// Where and with what a run was made.
struct RunInfo {
    std::string uuid;  ///< random; identifies the run across merged databases
    std::string started_at;
    std::string git_commit, compiler, flags;
    std::string cpu_model, governor, hostname;
    std::uint32_t cores = 0;
    std::uint32_t threads = 1;
    std::string shard;  ///< "K/N", or empty for the whole plan
    /// The program that made the run, its executable's name and build id (runner/binary_identity.h).
    std::string binary, binary_id;
    std::string experiment_hash;
    std::string experiment_content;

    /// This machine and binary, now.
    static RunInfo current(std::uint32_t threads, const std::string& shard, const Experiment& e);
};

/// The machine's state when a cell started (the noise floor): the 1-minute load average from
/// /proc/loadavg and the time of a fixed calibration loop (runner/run_experiment.h).
struct MachineState {
    double load_1m = 0;
    double calibration_ns = 0;
    double memory_ns = NAN;  ///< the memory probe (run_experiment.h); NaN where not measured
    int resampled = 0;       ///< times the runner waited and sampled again because the machine was slow
};

/// A cell whose calibration loop or memory probe ran more than this fraction slower than its
/// run's median was measured on a busy (or throttled) machine: it is flagged `slow`.
inline constexpr double kSlowCalibration = 0.10;

class ResultStore {
public:
    /// Opens for writing: creates the file (and its folder) if needed and migrates it.
    explicit ResultStore(const std::string& path);
    /// For tests of migrations: brings a database up to `version` only.
    ResultStore(const std::string& path, int version);

    Database& db() { return db_; }

    std::int64_t experiment_id(const Experiment& e);
    /// The newest unfinished run of the experiment with the same file content and shard that the
    /// program named `binary` began, if any: another program's run (rcbench's, or one with other
    /// structures registered) is not resumed, so every cell of a run comes from the program it
    /// names. A rebuild of the same program resumes its run, which keeps the build id and git commit
    /// it began with.
    std::optional<std::int64_t> unfinished_run(std::int64_t experiment_id, const std::string& experiment_hash,
                                               const std::string& shard, const std::string& binary);
    std::int64_t begin_run(std::int64_t experiment_id, const RunInfo& info);
    /// The run a runner of `e` works on: the newest unfinished run of the same file content, shard
    /// and binary name, or a new one (always new with `new_run`). One transaction, so runners started
    /// together on one database agree on one run instead of each starting its own.
    std::int64_t resume_or_begin_run(const Experiment& e, const RunInfo& info, bool new_run);
    /// The name of the program that made the run (run.binary), or nullopt when there is no such run.
    std::optional<std::string> run_binary(std::int64_t run_id);
    std::set<std::string> finished_cells(std::int64_t run_id);
    bool cell_done(std::int64_t run_id, const std::string& cell_key);
    /// Stores a finished cell with its frames in one transaction. Returns false (and stores nothing)
    /// when another runner stored the same cell of the same run first.
    bool store_cell(std::int64_t run_id, std::int64_t experiment_id, const Cell& cell, const SceneSpec& scene,
                    const Recording& recording, const std::string& scene_hash, const SimulationResult& result,
                    const std::optional<MachineState>& state = std::nullopt);
    void finish_run(std::int64_t run_id);
    /// Sets cell_state.slow for every cell of the run from the run's median calibration time
    /// (kSlowCalibration); returns how many are flagged. Called after each runner pass, so the
    /// flags follow the median as a resumed run grows.
    std::size_t flag_slow_cells(std::int64_t run_id);
    /// The stored ray-cast and update medians of the run's cells, by cell key.
    std::map<std::string, std::pair<double, double>> cell_medians(std::int64_t run_id);

private:
    void migrate(int target);
    std::int64_t scene_id(const SceneSpec& spec, const Recording& recording, const std::string& hash);
    std::int64_t config_id(const std::string& structure, const nlohmann::json& params);

    Database db_;
};

/// A frame_kind row (docs/database.md) in column order: what store_cell and merge write.
inline constexpr const char* kFrameKindInsertSql =
    "INSERT INTO frame_kind(cell_id, frame, kind, rays, raycast_ns, raycast_wall_ns, hits, n_t, n_rb, n_tp, n_ro, "
    "n_ro_hits, n_th, n_mp, n_miss, n_dup) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)";

/// The runs whose cells make up run R's plan, as SQL for `cell.run_id IN <this>` with R bound to
/// both of its two parameters: R itself and, when R is shard K/N, the newest run of every other
/// shard J/N of the same experiment file (a cluster run merged into one database).
inline constexpr const char* kRunGroupSql =
    "(SELECT ? UNION SELECT max(sib.id) FROM run AS me JOIN run AS sib ON sib.experiment_id = me.experiment_id "
    "AND sib.experiment_hash = me.experiment_hash AND sib.shard != me.shard "
    "AND substr(sib.shard, instr(sib.shard, '/')) = substr(me.shard, instr(me.shard, '/')) "
    "WHERE me.id = ? AND me.shard != '' GROUP BY sib.shard)";

/// scene.name as tables and charts show it: a name over 80 characters is cut to 64 and ends in "..."
/// and 12 hex digits of the scene's content hash, so distinct scenes stay distinct and a name of
/// megabytes is not copied into every row, chart and caption. In SQL, so the long text never leaves
/// SQLite.
inline constexpr const char* kSceneLabelSql =
    "(CASE WHEN length(scene.name) <= 80 THEN scene.name ELSE substr(scene.name, 1, 64) || '...' || "
    "substr(scene.hash, 1, 12) END)";

/// One stored cell, as the run summaries show it.
struct CellSummary {
    std::string scene, structure;
    nlohmann::json params;
    double raycast_ns_median = 0, update_ns_median = 0;
    std::int64_t mismatches = 0;
    bool slow = false;  ///< measured while the calibration loop ran slow (cell_state.slow)
};
/// The cells of a run.
std::vector<CellSummary> cell_summaries(Database& db, std::int64_t run_id);

/// A (scene, configuration)'s time over its repetitions in one run (table cell_interval): the
/// median of the repetitions' ray-cast and update medians and the 95% interval between the
/// repetitions planned before the run (core/base/statistics.h). Below two planned
/// repetitions low = high = median.
struct CellInterval {
    std::string scene, structure;
    nlohmann::json params;
    RepetitionInterval raycast, update;
};
/// The repetitions run `run_id`'s experiment file planned (its "repetitions"; 1 when it names none):
/// those of a cell's repetitions whose index is below this are the ones its interval rests on.
std::int64_t planned_repetitions(Database& db, std::int64_t run_id);
/// The cell_interval rows of a run.
std::vector<CellInterval> cell_intervals(Database& db, std::int64_t run_id);
/// Rewrites the run's cell_interval rows from its stored cells, one per (scene, configuration).
/// Runs in the caller's transaction (store_cell does this for the cell's pair; merge for each run
/// it adds cells to).
void store_cell_intervals(Database& db, std::int64_t run_id);

/// Opens an existing database read-only; refuses a newer schema; an older one is read through a
/// migrated copy in memory (the file is not changed); InputError if it does not exist.
std::unique_ptr<Database> open_read_only(const std::string& path);

/// Now, as ISO 8601 UTC ("2026-11-22T03:25:57Z"): the timestamps every table stores.
std::string utc_now();

/// Content hash of a recording (of its encoded bytes).
std::string recording_hash(const Recording& r);

/// A scene's features (table scene_feature): stored when the runner first stores a cell of the
/// scene; absent for scenes stored by an rcbench older than the table.
void store_scene_features(Database& db, std::int64_t scene_id, const SceneFeatures& features);
std::optional<SceneFeatures> stored_scene_features(Database& db, std::int64_t scene_id);

}  // namespace rcb
