#include "runner/store.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <thread>

#include "core/base/error.h"
#include "core/base/statistics.h"
#include "core/scene/recording_io.h"
#include "runner/binary_identity.h"
#include "runner/build_info.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

/// Forward-only migrations: entry i brings a database from user_version i to i + 1. Never edit a
/// released entry; append a new one.
const std::vector<const char*>& migrations() {
    static const std::vector<const char*> all = {
        // 0 → 1: the initial schema.
        R"sql(
CREATE TABLE experiment (
    id          INTEGER PRIMARY KEY,
    name        TEXT NOT NULL UNIQUE,
    description TEXT NOT NULL DEFAULT ''
);
CREATE TABLE run (
    id                 INTEGER PRIMARY KEY,
    uuid               TEXT NOT NULL UNIQUE,
    experiment_id      INTEGER NOT NULL REFERENCES experiment(id),
    experiment_hash    TEXT NOT NULL,
    experiment_content TEXT NOT NULL,
    started_at         TEXT NOT NULL,
    finished_at        TEXT,
    git_commit         TEXT NOT NULL,
    compiler           TEXT NOT NULL,
    flags              TEXT NOT NULL,
    cpu_model          TEXT NOT NULL,
    cores              INTEGER NOT NULL,
    governor           TEXT NOT NULL,
    hostname           TEXT NOT NULL,
    threads            INTEGER NOT NULL,
    shard              TEXT NOT NULL
);
CREATE TABLE scene (
    id             INTEGER PRIMARY KEY,
    hash           TEXT NOT NULL UNIQUE,
    name           TEXT NOT NULL,
    spec           TEXT NOT NULL,
    meta           TEXT NOT NULL,
    objects        INTEGER NOT NULL,
    frames         INTEGER NOT NULL,
    rays_per_frame REAL NOT NULL,
    stats          TEXT NOT NULL
);
CREATE TABLE config (
    id        INTEGER PRIMARY KEY,
    structure TEXT NOT NULL,
    params    TEXT NOT NULL,
    UNIQUE (structure, params)
);
CREATE TABLE cell (
    id                INTEGER PRIMARY KEY,
    run_id            INTEGER NOT NULL REFERENCES run(id),
    cell_key          TEXT NOT NULL,
    scene_id          INTEGER NOT NULL REFERENCES scene(id),
    config_id         INTEGER NOT NULL REFERENCES config(id),
    repetition        INTEGER NOT NULL,
    finished_at       TEXT NOT NULL,
    objects           INTEGER NOT NULL,
    build_ns          INTEGER NOT NULL,
    memory_bytes      INTEGER NOT NULL,
    verified          INTEGER NOT NULL,
    mismatches        INTEGER NOT NULL,
    frames            INTEGER NOT NULL,
    update_ns_median  REAL NOT NULL,
    update_ns_mad     REAL NOT NULL,
    raycast_ns_median REAL NOT NULL,
    raycast_ns_mad    REAL NOT NULL,
    UNIQUE (run_id, cell_key)
);
CREATE TABLE frame (
    cell_id      INTEGER NOT NULL REFERENCES cell(id) ON DELETE CASCADE,
    frame        INTEGER NOT NULL,
    warmup       INTEGER NOT NULL,
    inserts      INTEGER NOT NULL,
    removes      INTEGER NOT NULL,
    moves        INTEGER NOT NULL,
    rays         INTEGER NOT NULL,
    update_ns    INTEGER NOT NULL,
    raycast_ns   INTEGER NOT NULL,
    hits         INTEGER NOT NULL,
    missed       INTEGER NOT NULL,
    extra        INTEGER NOT NULL,
    duplicate    INTEGER NOT NULL,
    n_t          INTEGER NOT NULL,
    n_rb         INTEGER NOT NULL,
    n_tp         INTEGER NOT NULL,
    memory_bytes INTEGER NOT NULL,
    sah_cost     REAL,
    stats        TEXT NOT NULL,
    PRIMARY KEY (cell_id, frame)
);
CREATE INDEX cell_by_config ON cell(config_id, scene_id);
CREATE VIEW cell_summary AS
    SELECT cell.id AS cell_id, run.id AS run_id, run.git_commit, experiment.name AS experiment, scene.name AS scene,
           config.structure, config.params, cell.repetition, cell.objects, cell.build_ns, cell.memory_bytes,
           cell.update_ns_median, cell.raycast_ns_median, cell.mismatches
    FROM cell JOIN run ON run.id = cell.run_id JOIN experiment ON experiment.id = run.experiment_id
              JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id;
)sql",
        // 1 → 2: the analysis stage's cost-model fits (analysis/cost_model.h).
        R"sql(
CREATE TABLE fit (
    id               INTEGER PRIMARY KEY,
    run_id           INTEGER NOT NULL REFERENCES run(id),
    created_at       TEXT NOT NULL,
    structure        TEXT NOT NULL,
    target           TEXT NOT NULL,
    model            TEXT NOT NULL,
    terms            TEXT NOT NULL,
    observations     INTEGER NOT NULL,
    configurations   INTEGER NOT NULL,
    r2               REAL NOT NULL,
    rmse_relative    REAL NOT NULL,
    heldout_error    REAL NOT NULL,
    condition_number REAL NOT NULL,
    status           TEXT NOT NULL,
    chosen           INTEGER NOT NULL
);
CREATE TABLE fit_coefficient (
    fit_id     INTEGER NOT NULL REFERENCES fit(id) ON DELETE CASCADE,
    name       TEXT NOT NULL,
    value      REAL NOT NULL,
    ci_low     REAL,
    ci_high    REAL,
    spans_zero INTEGER NOT NULL,
    PRIMARY KEY (fit_id, name)
);
)sql",
        // 2 → 3: the tuner's results (tuner/tuning.h).
        R"sql(
CREATE TABLE tuning (
    id                  INTEGER PRIMARY KEY,
    name                TEXT NOT NULL,
    category            TEXT NOT NULL,
    structure           TEXT NOT NULL,
    mode                TEXT NOT NULL,
    algorithm           TEXT NOT NULL,
    created_at          TEXT NOT NULL,
    git_commit          TEXT NOT NULL,
    spec                TEXT NOT NULL,
    evaluations         INTEGER NOT NULL,
    measurements        INTEGER NOT NULL,
    seconds             REAL NOT NULL,
    stop_reason         TEXT NOT NULL,
    on_bound            TEXT NOT NULL,
    best_params         TEXT NOT NULL,
    best_measured_ms    REAL NOT NULL,
    best_measured_mad   REAL NOT NULL,
    best_predicted_ms   REAL,
    default_params      TEXT NOT NULL,
    default_measured_ms REAL,
    chosen              INTEGER NOT NULL
);
CREATE TABLE tuning_evaluation (
    tuning_id INTEGER NOT NULL REFERENCES tuning(id) ON DELETE CASCADE,
    i         INTEGER NOT NULL,
    params    TEXT NOT NULL,
    cost_ms   REAL NOT NULL,
    kind      TEXT NOT NULL,
    PRIMARY KEY (tuning_id, i)
);
)sql",
        // 3 → 4: the machine's state with each cell (the noise floor): the 1-minute load average and
        // a fixed calibration loop timed just before the cell ran, and whether that loop ran more
        // than 10% slower than the run's median (the cell was measured on a busy machine). The
        // cell_summary view gains the three columns (LEFT JOIN: cells of older runs show NULL).
        R"sql(
CREATE TABLE cell_state (
    cell_id        INTEGER PRIMARY KEY REFERENCES cell(id) ON DELETE CASCADE,
    load_1m        REAL NOT NULL,
    calibration_ns REAL NOT NULL,
    slow           INTEGER NOT NULL DEFAULT 0
);
DROP VIEW cell_summary;
CREATE VIEW cell_summary AS
    SELECT cell.id AS cell_id, run.id AS run_id, run.git_commit, experiment.name AS experiment, scene.name AS scene,
           config.structure, config.params, cell.repetition, cell.objects, cell.build_ns, cell.memory_bytes,
           cell.update_ns_median, cell.raycast_ns_median, cell.mismatches,
           cell_state.load_1m, cell_state.calibration_ns, cell_state.slow
    FROM cell JOIN run ON run.id = cell.run_id JOIN experiment ON experiment.id = run.experiment_id
              JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id
              LEFT JOIN cell_state ON cell_state.cell_id = cell.id;
)sql",
        // 4 → 5: scene features (sim/scene_features.h) and the categories derived from them by
        // clustering a run's scenes (analysis/scene_categories.h; thesis §7.2).
        R"sql(
CREATE TABLE scene_feature (
    scene_id INTEGER NOT NULL REFERENCES scene(id) ON DELETE CASCADE,
    name     TEXT NOT NULL,
    value    REAL NOT NULL,
    PRIMARY KEY (scene_id, name)
);
CREATE TABLE scene_clustering (
    run_id     INTEGER PRIMARY KEY REFERENCES run(id),
    created_at TEXT NOT NULL,
    seed       INTEGER NOT NULL,
    k          INTEGER NOT NULL,
    silhouette REAL,
    clustering TEXT NOT NULL
);
CREATE TABLE derived_category (
    run_id   INTEGER NOT NULL REFERENCES run(id),
    category INTEGER NOT NULL,
    name     TEXT NOT NULL,
    scenes   INTEGER NOT NULL,
    centroid TEXT NOT NULL,
    PRIMARY KEY (run_id, category)
);
CREATE TABLE derived_category_scene (
    run_id   INTEGER NOT NULL REFERENCES run(id),
    scene_id INTEGER NOT NULL REFERENCES scene(id),
    category INTEGER NOT NULL,
    PRIMARY KEY (run_id, scene_id)
);
)sql",
        // 5 → 6: the machine behind a run and the model's validation (runner/calibration.h,
        // analysis/cost_model.h): the CPU's data caches, each structure's calibration micro-scenes,
        // and per fit its leave-one-scene-out error and why terms were dropped.
        R"sql(
CREATE TABLE run_cache (
    run_id     INTEGER NOT NULL REFERENCES run(id),
    level      INTEGER NOT NULL,
    type       TEXT NOT NULL,
    size_bytes INTEGER NOT NULL
);
CREATE TABLE calibration (
    run_id     INTEGER NOT NULL REFERENCES run(id),
    structure  TEXT NOT NULL,
    params     TEXT NOT NULL,
    scene      TEXT NOT NULL,
    rays       INTEGER NOT NULL,
    n_rb       REAL NOT NULL,
    n_t        REAL NOT NULL,
    ns_per_ray REAL NOT NULL,
    mad        REAL NOT NULL
);
ALTER TABLE fit ADD COLUMN loso_error REAL;
ALTER TABLE fit ADD COLUMN notes TEXT NOT NULL DEFAULT '';
)sql",
        // 6 → 7: accuracy against the shapes' truth and the narrow phase's counters per frame
        // (sim/simulator.h FrameResult; thesis eq. 5.3). Frames stored before this version are of
        // box-only scenes at the box level, where the shapes' truth is the boxes' truth: their
        // accuracy follows from the mismatch counts they have (returned: distinct objects
        // reported; correct: those not clearly missed; relevant: those plus the missed ones), and
        // they ran no shape test. A tuning records the accuracy its choice had to meet (tuner/accuracy.h;
        // before: exact).
        R"sql(
ALTER TABLE frame ADD COLUMN returned INTEGER NOT NULL DEFAULT 0;
ALTER TABLE frame ADD COLUMN correct INTEGER NOT NULL DEFAULT 0;
ALTER TABLE frame ADD COLUMN relevant INTEGER NOT NULL DEFAULT 0;
ALTER TABLE frame ADD COLUMN n_ro INTEGER NOT NULL DEFAULT 0;
ALTER TABLE frame ADD COLUMN n_ro_hits INTEGER NOT NULL DEFAULT 0;
ALTER TABLE tuning ADD COLUMN accuracy TEXT NOT NULL DEFAULT 'exact';
UPDATE frame SET returned = max(hits - duplicate, 0), correct = max(hits - duplicate - extra, 0),
                 relevant = max(hits - duplicate - extra, 0) + missed;
)sql",
        // 7 → 8: the node boxes a tree's traversal hit per frame (accel/model/counters.h n_th; the cost
        // model's C_TH). 0 where not counted: grids, peers, and frames stored before.
        R"sql(
ALTER TABLE frame ADD COLUMN n_th INTEGER NOT NULL DEFAULT 0;
)sql",
        // 8 → 9: the traversal steps whose outcome a history predictor missed, per frame and per
        // calibration micro-scene (accel/model/outcome_predictor.h n_mp; the cost model's C_MP). 0 where
        // not counted: brute force, Embree, and frames stored before.
        R"sql(
ALTER TABLE frame ADD COLUMN n_mp INTEGER NOT NULL DEFAULT 0;
ALTER TABLE calibration ADD COLUMN n_mp REAL NOT NULL DEFAULT 0;
)sql",
        // 9 → 10: measurements that repeat. Which clock a cell's times are on (core/base/stopwatch.h:
        // the thread's CPU time when its work runs on one thread; cells stored before were wall
        // time), the 95% interval of each median over the cell's frames, each frame's wall times
        // beside the clock's, the memory probe beside the integer loop, and how often the runner
        // sampled the machine again before measuring because it was slow (cell_state.resampled).
        // And the cost model's validations: nested splits of one run, and a model frozen on one run
        // predicting another (analysis/validation.h).
        R"sql(
ALTER TABLE cell ADD COLUMN clock TEXT NOT NULL DEFAULT 'wall';
ALTER TABLE cell ADD COLUMN update_ns_ci_low REAL;
ALTER TABLE cell ADD COLUMN update_ns_ci_high REAL;
ALTER TABLE cell ADD COLUMN raycast_ns_ci_low REAL;
ALTER TABLE cell ADD COLUMN raycast_ns_ci_high REAL;
ALTER TABLE frame ADD COLUMN update_wall_ns INTEGER;
ALTER TABLE frame ADD COLUMN raycast_wall_ns INTEGER;
ALTER TABLE cell_state ADD COLUMN resampled INTEGER NOT NULL DEFAULT 0;
ALTER TABLE cell_state ADD COLUMN memory_ns REAL;
CREATE TABLE model_validation (
    id                  INTEGER PRIMARY KEY,
    run_id              INTEGER NOT NULL REFERENCES run(id),
    created_at          TEXT NOT NULL,
    train               TEXT NOT NULL,
    train_run_uuid      TEXT NOT NULL,
    split               TEXT NOT NULL,
    splits              TEXT NOT NULL,
    structure           TEXT NOT NULL,
    cells               INTEGER NOT NULL,
    unpredictable       INTEGER NOT NULL,
    scenes              INTEGER NOT NULL,
    frame_median        REAL,
    frame_median_low    REAL,
    frame_median_high   REAL,
    frame_p90           REAL,
    frame_p90_low       REAL,
    frame_p90_high      REAL,
    raycast_median      REAL,
    raycast_median_low  REAL,
    raycast_median_high REAL,
    raycast_p90         REAL,
    raycast_p90_low     REAL,
    raycast_p90_high    REAL,
    resamples           INTEGER NOT NULL,
    seed                INTEGER NOT NULL,
    models              TEXT NOT NULL
);
)sql",
        // 10 → 11: per query kind, a frame's rays cast as their own timed batch and counted on their
        // own (sim/simulator.h KindResult): stored only for frames with a ray of another kind
        // than all, so databases of all-hits runs do not grow. Rays, times, hits and counters sum
        // to the frame row's.
        R"sql(
CREATE TABLE frame_kind (
    cell_id         INTEGER NOT NULL REFERENCES cell(id) ON DELETE CASCADE,
    frame           INTEGER NOT NULL,
    kind            TEXT NOT NULL,
    rays            INTEGER NOT NULL,
    raycast_ns      INTEGER NOT NULL,
    raycast_wall_ns INTEGER NOT NULL,
    hits            INTEGER NOT NULL,
    n_t             INTEGER NOT NULL,
    n_rb            INTEGER NOT NULL,
    n_tp            INTEGER NOT NULL,
    n_ro            INTEGER NOT NULL,
    n_ro_hits       INTEGER NOT NULL,
    n_th            INTEGER NOT NULL,
    n_mp            INTEGER NOT NULL,
    PRIMARY KEY (cell_id, frame, kind),
    FOREIGN KEY (cell_id, frame) REFERENCES frame(cell_id, frame) ON DELETE CASCADE
);
)sql",
        // 11 → 12: a (scene, configuration)'s time over its repetitions in a run: the median of the
        // repetitions' medians and its 95% interval between the planned ones (repetition_interval.h;
        // NULL bounds below two planned repetitions). Kept equal to the stored cells: rewritten with each
        // cell stored and each merge, and filled for the runs a database already holds when it is
        // migrated (apply_migrations).
        R"sql(
CREATE TABLE cell_interval (
    run_id            INTEGER NOT NULL REFERENCES run(id),
    scene_id          INTEGER NOT NULL REFERENCES scene(id),
    config_id         INTEGER NOT NULL REFERENCES config(id),
    repetitions       INTEGER NOT NULL,
    raycast_ns_median REAL NOT NULL,
    raycast_ns_low    REAL,
    raycast_ns_high   REAL,
    update_ns_median  REAL NOT NULL,
    update_ns_low     REAL,
    update_ns_high    REAL,
    PRIMARY KEY (run_id, scene_id, config_id)
);
)sql",
        // 12 → 13: the lines a simulated private cache fetched for a frame's batch, and for each
        // kind's (accel/model/cache_model.h n_miss; the cost model's C_MISS). 0 where not counted:
        // brute force, the peers, and frames stored before.
        R"sql(
ALTER TABLE frame ADD COLUMN n_miss INTEGER NOT NULL DEFAULT 0;
ALTER TABLE frame_kind ADD COLUMN n_miss INTEGER NOT NULL DEFAULT 0;
)sql",
        // 13 → 14: the cells, entries and nodes a frame's update wrote (Structure::writes; the cost
        // model's c_write). 0 where not counted: brute force, the peers, and frames stored before.
        R"sql(
ALTER TABLE frame ADD COLUMN writes INTEGER NOT NULL DEFAULT 0;
)sql",
        // 14 → 15: the lines each calibration micro-scene's rays fetched per ray (CalibrationPoint::n_miss;
        // the prior of the cost model's C_MISS). 0 in calibrations stored before.
        R"sql(
ALTER TABLE calibration ADD COLUMN n_miss REAL NOT NULL DEFAULT 0;
)sql",
        // 15 → 16: the objects each calibration micro-scene's rays reported per ray
        // (CalibrationPoint::n_tp: the calibration's C_HIT). 0 in calibrations stored before.
        R"sql(
ALTER TABLE calibration ADD COLUMN n_tp REAL NOT NULL DEFAULT 0;
)sql",
        // 16 → 17: calibration passes spread over a run (runner/calibration.h add_calibration_pass);
        // the fit reads each micro-scene's fastest. Calibrations stored before are pass 0.
        R"sql(
ALTER TABLE calibration ADD COLUMN pass INTEGER NOT NULL DEFAULT 0;
)sql",
        // 17 → 18: the cells a validation priced beyond the counters' range its model was fitted
        // on (analysis/cost_model.h outside_trained_range). 0 in validations stored before.
        R"sql(
ALTER TABLE model_validation ADD COLUMN outside_range INTEGER NOT NULL DEFAULT 0;
)sql",
        // 18 → 19: the box hits a grid dropped because the ray had already reported the object in
        // another cell (Counters::n_dup), per frame, per kind's batch and per calibration micro-scene
        // ray (docs/model.md, "Hits"). 0 where not counted: every structure but the grids, and
        // everything stored before.
        R"sql(
ALTER TABLE frame ADD COLUMN n_dup INTEGER NOT NULL DEFAULT 0;
ALTER TABLE frame_kind ADD COLUMN n_dup INTEGER NOT NULL DEFAULT 0;
ALTER TABLE calibration ADD COLUMN n_dup REAL NOT NULL DEFAULT 0;
)sql",
        // 19 → 20: the program that made a run (runner/binary_identity.h): its executable's name and
        // build id, so that the runs of a program linking rcbench::cli with its own structures stay
        // apart from rcbench's. Runs stored before were made by the rcbench executable (no other
        // program could link the runner then; the test programs' databases are temporary); their
        // build id was not recorded ('').
        R"sql(
ALTER TABLE run ADD COLUMN binary TEXT NOT NULL DEFAULT 'rcbench';
ALTER TABLE run ADD COLUMN binary_id TEXT NOT NULL DEFAULT '';
)sql",
        // 20 → 21: the update's work beyond its writes (Structure::update_work: keys a linear BVH's
        // radix sort placed, blocks a wide BVH's descents read; the cost model's c_work), per frame.
        // 0 where a structure counts none; NULL in frames stored before, which did not record it:
        // a form that prices it is then not offered, rather than fitted to zeros.
        R"sql(
ALTER TABLE frame ADD COLUMN update_work INTEGER;
)sql",
        // 21 → 22: what each calibration point measured (runner/calibration.h): the batches both
        // timed and counted, and whether the structure's calibration budget cut it short. Every
        // calibration stored before timed and counted 7 batches in full (the pass's only setting then).
        R"sql(
ALTER TABLE calibration ADD COLUMN repeats INTEGER NOT NULL DEFAULT 7;
ALTER TABLE calibration ADD COLUMN cut INTEGER NOT NULL DEFAULT 0;
)sql",
    };
    return all;
}

int user_version(Database& db) {
    Statement s = db.prepare("PRAGMA user_version");
    s.step();
    return int(s.int64(0));
}

void refuse_newer(int version, const std::string& path) {
    if (version < 0)
        throw InputError(path + ": not an rcbench results database (schema version " + std::to_string(version) + ")");
    if (version > latest_schema_version())
        throw InputError(path + ": results database schema version " + std::to_string(version) +
                         " is newer than this rcbench writes (" + std::to_string(latest_schema_version()) +
                         "); use a newer rcbench");
}

/// The schema version that added cell_interval.
constexpr int kCellIntervalVersion = 12;

/// Brings `db` from schema `from` to `to`: the migrations in order, then the version stamp. The
/// runs already stored get their cell_interval rows, which SQL alone cannot compute.
void apply_migrations(Database& db, int from, int to) {
    for (int v = from; v < to; ++v) db.exec(migrations()[std::size_t(v)]);
    if (from < kCellIntervalVersion && to >= kCellIntervalVersion) {
        std::vector<std::int64_t> runs;
        Statement s = db.prepare("SELECT id FROM run");
        while (s.step()) runs.push_back(s.int64(0));
        for (const std::int64_t run : runs) store_cell_intervals(db, run);
    }
    if (to > from) db.exec("PRAGMA user_version = " + std::to_string(to));
}

/// The tables, views and indexes as SQLite stores them (name → CREATE statement).
std::map<std::string, std::string> schema_of(Database& db) {
    std::map<std::string, std::string> out;
    Statement s = db.prepare("SELECT name, sql FROM sqlite_master WHERE name NOT LIKE 'sqlite_%' AND sql IS NOT NULL");
    while (s.step()) out[s.text(0)] = s.text(1);
    return out;
}

/// InputError unless the file's schema is exactly what the migrations make at its version: a
/// database with a table dropped or altered is damaged, and would fail later with a bare
/// "no such table" in the middle of a command.
void check_schema(Database& db, int version) {
    Database reference(":memory:", false);
    apply_migrations(reference, 0, version);
    const auto want = schema_of(reference), have = schema_of(db);
    for (const auto& [name, sql] : want) {
        auto it = have.find(name);
        if (it == have.end()) throw InputError(db.path() + ": damaged results database (" + name + " is missing)");
        if (it->second != sql)
            throw InputError(db.path() + ": damaged results database (" + name + " differs from schema version " +
                             std::to_string(version) + ")");
    }
}

}  // namespace

std::string utc_now() {
    const auto t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

namespace {

std::string first_line_of(const std::string& path) {
    std::ifstream in(path);
    std::string line;
    std::getline(in, line);
    return line;
}

std::string read_cpu_model() {
    std::ifstream in("/proc/cpuinfo");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
    return "unknown";
}

std::string random_uuid() {
    std::random_device rd;
    std::uniform_int_distribution<std::uint64_t> dist;
    const std::uint64_t a = dist(rd), b = dist(rd);
    char buf[40];
    std::snprintf(buf, sizeof buf, "%016llx%016llx", (unsigned long long)a, (unsigned long long)b);
    return buf;
}

nlohmann::json scene_stats(const Recording& r) {
    const Aabb b = bounds_of(r.initial);
    std::vector<double> edges;
    for (const Object& o : r.initial) edges.push_back(o.box.longest_edge());
    std::sort(edges.begin(), edges.end());
    auto q = [&](double p) { return order_statistic(edges, p); };
    return {{"bounds", {{b.min.x, b.min.y, b.min.z}, {b.max.x, b.max.y, b.max.z}}},
            {"longest_edge", {{"min", q(0)}, {"p10", q(0.1)}, {"median", q(0.5)}, {"p90", q(0.9)}, {"max", q(1)}}}};
}

}  // namespace

int latest_schema_version() { return int(migrations().size()); }

RunInfo RunInfo::current(std::uint32_t threads, const std::string& shard, const Experiment& e) {
    RunInfo r;
    r.uuid = random_uuid();
    r.started_at = utc_now();
    r.git_commit = kGitCommit;
    r.compiler = kCompiler;
    r.flags = kCompileFlags;
    r.binary = this_binary().name;
    r.binary_id = this_binary().build_id;
    r.cpu_model = read_cpu_model();
    r.cores = std::thread::hardware_concurrency();
    r.governor = first_line_of("/sys/devices/system/cpu/cpu0/cpufreq/scaling_governor");
    if (r.governor.empty()) r.governor = "unreadable";
    char host[256] = {0};
    gethostname(host, sizeof host - 1);
    r.hostname = host;
    r.threads = threads;
    r.shard = shard;
    r.experiment_hash = e.hash;
    r.experiment_content = e.content;
    return r;
}

std::string recording_hash(const Recording& r) { return stable_hash(encode_recording(r)); }

void store_scene_features(Database& db, std::int64_t scene_id, const SceneFeatures& features) {
    Statement ins = db.prepare("INSERT OR REPLACE INTO scene_feature(scene_id, name, value) VALUES (?,?,?)");
    for (std::size_t i = 0; i < kSceneFeatureCount; ++i)
        ins.bind_all(scene_id, std::string(scene_feature_names()[i]), features.values[i]).run();
}

std::optional<SceneFeatures> stored_scene_features(Database& db, std::int64_t scene_id) {
    Statement s = db.prepare("SELECT name, value FROM scene_feature WHERE scene_id = ?");
    s.bind(1, scene_id);
    nlohmann::json j = nlohmann::json::object();
    while (s.step()) j[s.text(0)] = s.real(1);
    for (std::string_view name : scene_feature_names())
        if (!j.contains(std::string(name))) return std::nullopt;
    return SceneFeatures::from_json(j, "scene " + std::to_string(scene_id));
}

namespace {
Database open_for_writing(const std::string& path) {
    const fs::path parent = fs::path(path).parent_path();
    std::error_code ec;
    if (!parent.empty()) fs::create_directories(parent, ec);
    if (fs::is_directory(path)) throw InputError(path + ": is a directory, not a results database");
    try {
        return Database(path, false);
    } catch (const SqlError& e) {
        throw InputError(path + ": cannot open the results database (" + e.what() + ")");
    }
}
}  // namespace

ResultStore::ResultStore(const std::string& path) : ResultStore(path, latest_schema_version()) {}

ResultStore::ResultStore(const std::string& path, int version) : db_(open_for_writing(path)) {
    try {
        migrate(version);
    } catch (const SqlError& e) {
        throw InputError(path + ": not a usable results database (" + e.what() + ")");
    }
}

void ResultStore::migrate(int target) {
    Transaction t(db_);
    const int version = user_version(db_);
    refuse_newer(version, db_.path());
    if (version > 0) check_schema(db_, version);
    apply_migrations(db_, version, target);
    t.commit();
}

std::unique_ptr<Database> open_read_only(const std::string& path) {
    if (!fs::is_regular_file(path)) throw InputError(path + ": no such results database");
    std::unique_ptr<Database> db;
    try {
        db = std::make_unique<Database>(path, true);
        const int version = user_version(*db);
        refuse_newer(version, path);
        if (version == 0) throw InputError(path + ": not an rcbench results database (no schema)");
        check_schema(*db, version);
        // An older database is read through a migrated copy in memory, so every reader sees the
        // latest schema (empty new tables) and the file stays as it is.
        if (version < latest_schema_version()) {
            db = Database::in_memory_copy(*db);
            apply_migrations(*db, version, latest_schema_version());
        }
    } catch (const SqlError& e) {
        throw InputError(path + ": cannot read the results database (" + e.what() + ")");
    }
    return db;
}

std::int64_t ResultStore::experiment_id(const Experiment& e) {
    db_.prepare(
           "INSERT INTO experiment(name, description) VALUES (?, ?) ON CONFLICT(name) DO UPDATE SET description = "
           "excluded.description")
        .bind_all(e.name, e.description)
        .run();
    Statement s = db_.prepare("SELECT id FROM experiment WHERE name = ?");
    s.bind(1, e.name);
    s.step();
    return s.int64(0);
}

std::optional<std::int64_t> ResultStore::unfinished_run(std::int64_t experiment_id, const std::string& hash,
                                                        const std::string& shard, const std::string& binary) {
    Statement s = db_.prepare(
        "SELECT id FROM run WHERE experiment_id = ? AND experiment_hash = ? AND shard = ? AND binary = ? AND "
        "finished_at IS NULL ORDER BY id DESC LIMIT 1");
    s.bind_all(experiment_id, hash, shard, binary);
    if (s.step()) return s.int64(0);
    return std::nullopt;
}

std::int64_t ResultStore::begin_run(std::int64_t experiment_id, const RunInfo& r) {
    db_.prepare(
           "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, git_commit, "
           "compiler, flags, cpu_model, cores, governor, hostname, threads, shard, binary, binary_id) VALUES "
           "(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
        .bind_all(r.uuid, experiment_id, r.experiment_hash, r.experiment_content, r.started_at, r.git_commit,
                  r.compiler, r.flags, r.cpu_model, std::int64_t(r.cores), r.governor, r.hostname,
                  std::int64_t(r.threads), r.shard, r.binary, r.binary_id)
        .run();
    return db_.last_insert_id();
}

std::int64_t ResultStore::resume_or_begin_run(const Experiment& e, const RunInfo& info, bool new_run) {
    Transaction t(db_);
    const std::int64_t experiment = experiment_id(e);
    std::optional<std::int64_t> run;
    if (!new_run) run = unfinished_run(experiment, e.hash, info.shard, info.binary);
    if (!run) run = begin_run(experiment, info);
    t.commit();
    return *run;
}

std::optional<std::string> ResultStore::run_binary(std::int64_t run_id) {
    Statement s = db_.prepare("SELECT binary FROM run WHERE id = ?");
    s.bind(1, run_id);
    if (!s.step()) return std::nullopt;
    return s.text(0);
}

std::set<std::string> ResultStore::finished_cells(std::int64_t run_id) {
    std::set<std::string> keys;
    Statement s = db_.prepare("SELECT cell_key FROM cell WHERE run_id = ?");
    s.bind(1, run_id);
    while (s.step()) keys.insert(s.text(0));
    return keys;
}

bool ResultStore::cell_done(std::int64_t run_id, const std::string& key) {
    Statement s = db_.prepare("SELECT 1 FROM cell WHERE run_id = ? AND cell_key = ?");
    s.bind_all(run_id, key);
    return s.step();
}

std::int64_t ResultStore::scene_id(const SceneSpec& spec, const Recording& r, const std::string& hash) {
    std::size_t rays = 0;
    for (const Frame& f : r.frames) rays += f.rays.size();
    db_.prepare(
           "INSERT INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) VALUES (?,?,?,?,?,?,?,?) "
           "ON CONFLICT(hash) DO NOTHING")
        .bind_all(hash, spec.name, spec.key.dump(), r.meta, std::int64_t(r.initial.size()),
                  std::int64_t(r.frames.size()), r.frames.empty() ? 0.0 : double(rays) / double(r.frames.size()),
                  scene_stats(r).dump())
        .run();
    Statement s = db_.prepare("SELECT id FROM scene WHERE hash = ?");
    s.bind(1, hash);
    s.step();
    const std::int64_t id = s.int64(0);
    // Features once per scene (a scene stored by an older rcbench gets them when a run uses it again).
    Statement has = db_.prepare("SELECT 1 FROM scene_feature WHERE scene_id = ?");
    has.bind(1, id);
    if (!has.step()) store_scene_features(db_, id, compute_scene_features(r));
    return id;
}

std::int64_t ResultStore::config_id(const std::string& structure, const nlohmann::json& params) {
    db_.prepare("INSERT INTO config(structure, params) VALUES (?, ?) ON CONFLICT DO NOTHING")
        .bind_all(structure, params.dump())
        .run();
    Statement s = db_.prepare("SELECT id FROM config WHERE structure = ? AND params = ?");
    s.bind_all(structure, params.dump());
    s.step();
    return s.int64(0);
}

namespace {

/// Rewrites the cell_interval row of one (run, scene, configuration) from its stored cells: the
/// interval from the planned repetitions, the median over all (core/base/statistics.h).
void store_cell_interval(Database& db, std::int64_t run_id, std::int64_t scene_id, std::int64_t config_id,
                         std::int64_t planned) {
    std::vector<double> cast[2], update[2];  // [0]: planned repetitions, [1]: added ones
    Statement s = db.prepare(
        "SELECT repetition, raycast_ns_median, update_ns_median FROM cell WHERE run_id = ? AND scene_id = ? AND "
        "config_id = ? ORDER BY repetition");
    s.bind_all(run_id, scene_id, config_id);
    while (s.step()) {
        const int added = s.int64(0) >= planned ? 1 : 0;
        cast[added].push_back(s.real(1));
        update[added].push_back(s.real(2));
    }
    if (cast[0].empty() && cast[1].empty()) return;
    const RepetitionInterval c = repetition_interval(cast[0], cast[1]), u = repetition_interval(update[0], update[1]);
    const auto bound = [](const RepetitionInterval& r, double v) {
        return r.has_interval() ? std::optional<double>(v) : std::nullopt;
    };
    db.prepare(
          "INSERT OR REPLACE INTO cell_interval(run_id, scene_id, config_id, repetitions, raycast_ns_median, "
          "raycast_ns_low, raycast_ns_high, update_ns_median, update_ns_low, update_ns_high) VALUES "
          "(?,?,?,?,?,?,?,?,?,?)")
        .bind_all(run_id, scene_id, config_id, std::int64_t(c.repetitions), c.median, bound(c, c.low), bound(c, c.high),
                  u.median, bound(u, u.low), bound(u, u.high))
        .run();
}

}  // namespace

std::int64_t planned_repetitions(Database& db, std::int64_t run_id) {
    Statement s = db.prepare("SELECT experiment_content FROM run WHERE id = ?");
    s.bind(1, run_id);
    if (!s.step()) return 1;
    const nlohmann::json j = nlohmann::json::parse(s.text(0), nullptr, false);
    const auto it = j.is_object() ? j.find("repetitions") : j.end();
    return j.is_object() && it != j.end() && it->is_number_unsigned() && it->get<std::int64_t>() >= 1
               ? it->get<std::int64_t>()
               : 1;
}

void store_cell_intervals(Database& db, std::int64_t run_id) {
    db.prepare("DELETE FROM cell_interval WHERE run_id = ?").bind_all(run_id).run();
    std::vector<std::pair<std::int64_t, std::int64_t>> pairs;
    Statement s = db.prepare("SELECT DISTINCT scene_id, config_id FROM cell WHERE run_id = ?");
    s.bind(1, run_id);
    while (s.step()) pairs.emplace_back(s.int64(0), s.int64(1));
    const std::int64_t planned = planned_repetitions(db, run_id);
    for (const auto& pair : pairs) store_cell_interval(db, run_id, pair.first, pair.second, planned);
}

std::vector<CellInterval> cell_intervals(Database& db, std::int64_t run_id) {
    std::vector<CellInterval> out;
    Statement s = db.prepare("SELECT " + std::string(kSceneLabelSql) +
                             ", config.structure, config.params, repetitions, raycast_ns_median, raycast_ns_low, "
                             "raycast_ns_high, update_ns_median, update_ns_low, update_ns_high, (SELECT count(*) FROM "
                             "cell WHERE cell.run_id = cell_interval.run_id AND cell.scene_id = cell_interval.scene_id "
                             "AND cell.config_id = cell_interval.config_id AND cell.repetition < ?) FROM cell_interval "
                             "JOIN scene ON scene.id = cell_interval.scene_id "
                             "JOIN config ON config.id = cell_interval.config_id WHERE run_id = ?");
    s.bind_all(planned_repetitions(db, run_id), run_id);
    while (s.step()) {
        CellInterval row{s.text(0), s.text(1), nlohmann::json::parse(s.text(2)), {}, {}};
        for (int k = 0; k < 2; ++k) {
            RepetitionInterval& r = k == 0 ? row.raycast : row.update;
            const int at = 4 + 3 * k;
            r.repetitions = std::size_t(s.int64(3));
            r.planned = std::size_t(s.int64(10));
            r.median = s.real(at);
            r.low = s.is_null(at + 1) ? r.median : s.real(at + 1);
            r.high = s.is_null(at + 2) ? r.median : s.real(at + 2);
        }
        out.push_back(std::move(row));
    }
    return out;
}

bool ResultStore::store_cell(std::int64_t run_id, std::int64_t, const Cell& cell, const SceneSpec& spec,
                             const Recording& r, const std::string& scene_hash, const SimulationResult& res,
                             const std::optional<MachineState>& state) {
    Transaction t(db_);
    if (cell_done(run_id, cell.key)) return false;  // another runner was first; roll back nothing
    const std::int64_t scene = scene_id(spec, r, scene_hash);
    const std::int64_t config = config_id(res.structure, res.params);
    const Spread u = res.update_ns(), c = res.raycast_ns();
    db_.prepare(
           "INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, build_ns, "
           "memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, raycast_ns_median, "
           "raycast_ns_mad, clock, update_ns_ci_low, update_ns_ci_high, raycast_ns_ci_low, raycast_ns_ci_high) "
           "VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
        .bind_all(run_id, cell.key, scene, config, std::int64_t(cell.repetition), utc_now(), std::int64_t(res.objects),
                  std::int64_t(res.build_ns), std::int64_t(res.memory_bytes), std::int64_t(res.verified),
                  std::int64_t(res.mismatches()), std::int64_t(res.frames.size()), u.median, u.mad, c.median, c.mad,
                  std::string(clock_name(res.clock)), u.ci_low, u.ci_high, c.ci_low, c.ci_high)
        .run();
    const std::int64_t cell_id = db_.last_insert_id();
    if (state)
        db_.prepare(
               "INSERT INTO cell_state(cell_id, load_1m, calibration_ns, slow, resampled, memory_ns) VALUES "
               "(?,?,?,0,?,?)")
            .bind_all(cell_id, state->load_1m, state->calibration_ns, std::int64_t(state->resampled),
                      std::isfinite(state->memory_ns) ? std::optional<double>(state->memory_ns) : std::nullopt)
            .run();
    Statement f = db_.prepare(
        "INSERT INTO frame(cell_id, frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, hits, missed, "
        "extra, "
        "duplicate, n_t, n_rb, n_tp, memory_bytes, sah_cost, stats, returned, correct, relevant, n_ro, n_ro_hits, "
        "n_th, n_mp, n_miss, update_wall_ns, raycast_wall_ns, writes, n_dup, update_work) VALUES "
        "(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
    Statement kind = db_.prepare(kFrameKindInsertSql);
    for (const FrameResult& fr : res.frames) {
        std::optional<double> sah;
        if (fr.stats.contains("sah_cost") && fr.stats["sah_cost"].is_number()) sah = fr.stats["sah_cost"].get<double>();
        f.bind_all(cell_id, std::int64_t(fr.frame), std::int64_t(fr.warmup), std::int64_t(fr.inserts),
                   std::int64_t(fr.removes), std::int64_t(fr.moves), std::int64_t(fr.rays), std::int64_t(fr.update_ns),
                   std::int64_t(fr.raycast_ns), std::int64_t(fr.hits), std::int64_t(fr.missed), std::int64_t(fr.extra),
                   std::int64_t(fr.duplicate), std::int64_t(fr.counters.n_t), std::int64_t(fr.counters.n_rb),
                   std::int64_t(fr.counters.n_tp), std::int64_t(fr.memory_bytes), sah, fr.stats.dump(),
                   std::int64_t(fr.returned), std::int64_t(fr.correct), std::int64_t(fr.relevant),
                   std::int64_t(fr.counters.n_ro), std::int64_t(fr.counters.n_ro_hits), std::int64_t(fr.counters.n_th),
                   std::int64_t(fr.counters.n_mp), std::int64_t(fr.counters.n_miss), std::int64_t(fr.update.wall_ns),
                   std::int64_t(fr.raycast.wall_ns), std::int64_t(fr.writes), std::int64_t(fr.counters.n_dup),
                   std::int64_t(fr.update_work));
        f.run();
        for (const KindResult& k : fr.kinds)
            kind.bind_all(cell_id, std::int64_t(fr.frame), std::string(query_kind_name(k.kind)), std::int64_t(k.rays),
                          std::int64_t(k.raycast_ns), std::int64_t(k.raycast.wall_ns), std::int64_t(k.hits),
                          std::int64_t(k.counters.n_t), std::int64_t(k.counters.n_rb), std::int64_t(k.counters.n_tp),
                          std::int64_t(k.counters.n_ro), std::int64_t(k.counters.n_ro_hits),
                          std::int64_t(k.counters.n_th), std::int64_t(k.counters.n_mp), std::int64_t(k.counters.n_miss),
                          std::int64_t(k.counters.n_dup))
                .run();
    }
    store_cell_interval(db_, run_id, scene, config, planned_repetitions(db_, run_id));
    t.commit();
    return true;
}

std::vector<CellSummary> cell_summaries(Database& db, std::int64_t run_id) {
    std::vector<CellSummary> out;
    Statement s =
        db.prepare("SELECT " + std::string(kSceneLabelSql) +
                   ", config.structure, config.params, cell.raycast_ns_median, cell.update_ns_median, "
                   "cell.mismatches, coalesce(cell_state.slow, 0) "
                   "FROM cell JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id "
                   "LEFT JOIN cell_state ON cell_state.cell_id = cell.id WHERE cell.run_id = ?");
    s.bind(1, run_id);
    while (s.step())
        out.push_back({s.text(0), s.text(1), nlohmann::json::parse(s.text(2)), s.real(3), s.real(4), s.int64(5),
                       s.int64(6) != 0});
    return out;
}

std::map<std::string, std::pair<double, double>> ResultStore::cell_medians(std::int64_t run_id) {
    std::map<std::string, std::pair<double, double>> out;
    Statement s = db_.prepare("SELECT cell_key, raycast_ns_median, update_ns_median FROM cell WHERE run_id = ?");
    s.bind(1, run_id);
    while (s.step()) out[s.text(0)] = {s.real(1), s.real(2)};
    return out;
}

std::size_t ResultStore::flag_slow_cells(std::int64_t run_id) {
    Transaction t(db_);
    std::vector<double> loop, memory;
    {
        Statement s = db_.prepare(
            "SELECT cell_state.calibration_ns, cell_state.memory_ns FROM cell_state JOIN cell ON cell.id = "
            "cell_state.cell_id WHERE cell.run_id = ?");
        s.bind(1, run_id);
        while (s.step()) {
            loop.push_back(s.real(0));
            if (!s.is_null(1)) memory.push_back(s.real(1));
        }
    }
    if (loop.empty()) return 0;
    const double loop_limit = (1 + kSlowCalibration) * spread_of(loop).median;
    // Cells stored before the memory probe have NULL there: compared with nothing.
    const double memory_limit = memory.empty() ? 1e300 : (1 + kSlowCalibration) * spread_of(memory).median;
    db_.prepare(
           "UPDATE cell_state SET slow = (calibration_ns > ? OR coalesce(memory_ns > ?, 0)) "
           "WHERE cell_id IN (SELECT id FROM cell WHERE run_id = ?)")
        .bind_all(loop_limit, memory_limit, run_id)
        .run();
    Statement n = db_.prepare(
        "SELECT count(*) FROM cell_state JOIN cell ON cell.id = cell_state.cell_id WHERE cell.run_id = ? AND "
        "cell_state.slow = 1");
    n.bind(1, run_id);
    n.step();
    const std::size_t slow = std::size_t(n.int64(0));
    t.commit();
    return slow;
}

void ResultStore::finish_run(std::int64_t run_id) {
    db_.prepare("UPDATE run SET finished_at = ? WHERE id = ?").bind_all(utc_now(), run_id).run();
}

}  // namespace rcb
