#include "runner/results_reader.h"

#include <cmath>

#include "accel/model/counter_fields.h"
#include "runner/sqlite.h"
#include "runner/store.h"

namespace rcb {

namespace {

/// `sql`, whose run group (kRunGroupSql) is its only parameter pair, prepared and bound to run R.
Statement prepare_for_run(Database& db, const std::string& sql, std::int64_t run) {
    Statement s = db.prepare(sql);
    s.bind_all(run, run);
    return s;
}

std::string scene_label() { return kSceneLabelSql; }
std::string run_group() { return kRunGroupSql; }

}  // namespace

// ---------------------------------------------------------------------------------------------
// Runs

std::optional<StoredRun> read_stored_run(Database& db, std::int64_t run) {
    Statement s = db.prepare(
        "SELECT experiment.name, run.uuid, run.started_at, run.git_commit, run.cpu_model, run.compiler, run.cores, "
        "run.binary, run.binary_id FROM run JOIN experiment ON experiment.id = run.experiment_id WHERE run.id = ?");
    s.bind(1, run);
    if (!s.step()) return std::nullopt;
    return StoredRun{s.text(0), s.text(1),  s.text(2), s.text(3), s.text(4),
                     s.text(5), s.int64(6), s.text(7), s.text(8)};
}

bool run_exists(Database& db, std::int64_t run) {
    Statement s = db.prepare("SELECT id FROM run WHERE id = ?");
    s.bind(1, run);
    return s.step();
}

std::optional<std::int64_t> latest_measured_run(Database& db, const std::string& experiment) {
    Statement s = db.prepare(
        experiment.empty()
            ? "SELECT run.id FROM run WHERE EXISTS (SELECT 1 FROM cell WHERE cell.run_id = run.id) ORDER BY run.id "
              "DESC LIMIT 1"
            : "SELECT run.id FROM run JOIN experiment ON experiment.id = run.experiment_id WHERE experiment.name = ? "
              "AND EXISTS (SELECT 1 FROM cell WHERE cell.run_id = run.id) ORDER BY run.id DESC LIMIT 1");
    if (!experiment.empty()) s.bind(1, experiment);
    if (!s.step()) return std::nullopt;
    return s.int64(0);
}

std::optional<std::string> read_experiment_content(Database& db, std::int64_t run) {
    Statement s = db.prepare("SELECT experiment_content FROM run WHERE id = ?");
    s.bind(1, run);
    if (!s.step()) return std::nullopt;
    return s.text(0);
}

// ---------------------------------------------------------------------------------------------
// Cells

std::vector<CellTotalsRow> read_cell_totals(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(
        db,
        "SELECT cell.id, " + scene_label() +
            ", scene.spec, config.structure, config.params, cell.objects, cell.build_ns, cell.update_ns_median, "
            "cell.raycast_ns_median, cell.memory_bytes, cell.repetition, "
            "(SELECT sum(hits) FROM frame WHERE cell_id = cell.id AND warmup = 0), "
            "(SELECT sum(missed) FROM frame WHERE cell_id = cell.id), "
            "(SELECT sum(extra) FROM frame WHERE cell_id = cell.id), "
            "(SELECT sum(duplicate) FROM frame WHERE cell_id = cell.id), "
            "(SELECT sum(returned) FROM frame WHERE cell_id = cell.id AND warmup = 0), "
            "(SELECT sum(correct) FROM frame WHERE cell_id = cell.id AND warmup = 0), "
            "(SELECT sum(relevant) FROM frame WHERE cell_id = cell.id AND warmup = 0), "
            "cell.verified FROM cell JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = "
            "cell.config_id WHERE cell.run_id IN " +
            run_group() + " ORDER BY cell.id",
        run);
    std::vector<CellTotalsRow> out;
    while (s.step()) {
        CellTotalsRow r;
        r.id = s.int64(0);
        r.scene = s.text(1), r.spec = s.text(2), r.structure = s.text(3), r.params = s.text(4);
        r.objects = s.real(5), r.build_ns = s.real(6), r.update_ns = s.real(7), r.raycast_ns = s.real(8);
        r.memory_bytes = s.real(9);
        r.repetition = s.int64(10);
        r.hits = s.real(11), r.missed = s.real(12), r.extra = s.real(13), r.duplicate = s.real(14);
        r.returned = s.real(15), r.correct = s.real(16), r.relevant = s.real(17);
        r.verified = s.int64(18) != 0;
        out.push_back(std::move(r));
    }
    return out;
}

std::vector<CellCountsRow> read_cell_counts(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(
        db,
        "SELECT " + scene_label() +
            ", scene.spec, cell.objects, config.structure, config.params, cell.scene_id, cell.config_id, "
            "cell.memory_bytes, "
            "(SELECT 1.0 * sum(n_t) / max(sum(rays), 1) FROM frame WHERE cell_id = cell.id AND warmup = 0), "
            "(SELECT 1.0 * sum(n_rb) / max(sum(rays), 1) FROM frame WHERE cell_id = cell.id AND warmup = 0), "
            "(SELECT 1.0 * sum(n_tp) / max(sum(rays), 1) FROM frame WHERE cell_id = cell.id AND warmup = 0) "
            "FROM cell JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id "
            "WHERE cell.run_id IN " +
            run_group() + " ORDER BY cell.id",
        run);
    std::vector<CellCountsRow> out;
    while (s.step())
        out.push_back({s.text(0), s.text(1), s.text(3), s.text(4), s.int64(2), s.int64(5), s.int64(6), s.int64(7),
                       s.real(8), s.real(9), s.real(10)});
    return out;
}

std::vector<CellStateRow> read_cell_states(Database& db, std::int64_t run) {
    // Cells of runs made before the machine state have no cell_state row: NULL.
    Statement s = prepare_for_run(db,
                                  "SELECT config.structure, cell.scene_id, cell.config_id, cell.raycast_ns_median, "
                                  "cell.update_ns_median, cell_state.slow, cell_state.load_1m, "
                                  "cell_state.calibration_ns, cell.repetition "
                                  "FROM cell JOIN config ON config.id = cell.config_id "
                                  "LEFT JOIN cell_state ON cell_state.cell_id = cell.id WHERE cell.run_id IN " +
                                      run_group(),
                                  run);
    std::vector<CellStateRow> out;
    while (s.step()) {
        CellStateRow r;
        r.structure = s.text(0);
        r.scene_id = s.int64(1), r.config_id = s.int64(2), r.repetition = s.int64(8);
        r.raycast_ns_median = s.real(3), r.update_ns_median = s.real(4);
        r.has_state = !s.is_null(5);
        r.slow = s.int64(5) != 0;
        r.load_1m = s.real(6), r.calibration_ns = s.real(7);
        out.push_back(std::move(r));
    }
    return out;
}

std::vector<CellIdentityRow> read_cell_identities(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(db,
                                  "SELECT cell.scene_id, cell.config_id, config.structure, scene.hash, "
                                  "config.params, coalesce(cell_state.slow, 0) FROM cell "
                                  "JOIN config ON config.id = cell.config_id JOIN scene ON scene.id = "
                                  "cell.scene_id LEFT JOIN cell_state ON cell_state.cell_id = cell.id "
                                  "WHERE cell.run_id IN " +
                                      run_group(),
                                  run);
    std::vector<CellIdentityRow> out;
    while (s.step()) out.push_back({s.int64(0), s.int64(1), s.text(2), s.text(3), s.text(4), s.int64(5) != 0});
    return out;
}

std::vector<CellMediansRow> read_cell_medians(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(
        db, "SELECT scene_id, config_id, raycast_ns_median, update_ns_median FROM cell WHERE run_id IN " + run_group(),
        run);
    std::vector<CellMediansRow> out;
    while (s.step()) out.push_back({s.int64(0), s.int64(1), s.real(2), s.real(3)});
    return out;
}

std::vector<SlowCellRow> read_slow_cells(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(
        db,
        "SELECT " + scene_label() +
            ", config.structure, config.params, cell.repetition, cell_state.load_1m, "
            "cell_state.calibration_ns, cell.run_id FROM cell JOIN cell_state ON cell_state.cell_id = cell.id "
            "JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id "
            "WHERE cell_state.slow = 1 AND cell.run_id IN " +
            run_group() + " ORDER BY cell.id",
        run);
    std::vector<SlowCellRow> out;
    while (s.step()) out.push_back({s.text(0), s.text(1), s.text(2), s.int64(3), s.int64(6), s.real(4), s.real(5)});
    return out;
}

std::vector<CellCalibrationRow> read_cell_calibrations(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(db,
                                  "SELECT cell.run_id, cell_state.calibration_ns FROM cell JOIN cell_state ON "
                                  "cell_state.cell_id = cell.id WHERE cell.run_id IN " +
                                      run_group(),
                                  run);
    std::vector<CellCalibrationRow> out;
    while (s.step()) out.push_back({s.int64(0), s.real(1)});
    return out;
}

// ---------------------------------------------------------------------------------------------
// Frames

std::vector<FrameSeriesRow> read_frame_series(Database& db, std::int64_t cell) {
    Statement s = db.prepare("SELECT raycast_ns, sah_cost FROM frame WHERE cell_id = ? ORDER BY frame");
    s.bind(1, cell);
    std::vector<FrameSeriesRow> out;
    while (s.step()) out.push_back({s.real(0), s.is_null(1) ? NAN : s.real(1)});
    return out;
}

std::vector<FrameTimeRow> read_frame_times(Database& db, std::int64_t run) {
    // Warm-up frames are left out, as in the cell's own median (sim/simulator.h).
    Statement s = prepare_for_run(db,
                                  "SELECT cell.scene_id, cell.config_id, frame.frame, frame.raycast_ns, "
                                  "frame.update_ns FROM frame JOIN cell ON cell.id = frame.cell_id WHERE "
                                  "frame.warmup = 0 AND cell.run_id IN " +
                                      run_group(),
                                  run);
    std::vector<FrameTimeRow> out;
    while (s.step()) out.push_back({s.int64(0), s.int64(1), s.int64(2), s.real(3), s.real(4)});
    return out;
}

std::vector<FrameTimeRow> read_fastest_frame_times(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(db,
                                  "SELECT cell.scene_id, cell.config_id, frame.frame, "
                                  "min(frame.raycast_ns), min(frame.update_ns) FROM frame JOIN cell ON "
                                  "cell.id = frame.cell_id WHERE frame.warmup = 0 AND cell.run_id IN " +
                                      run_group() + " GROUP BY cell.scene_id, cell.config_id, frame.frame",
                                  run);
    std::vector<FrameTimeRow> out;
    while (s.step()) out.push_back({s.int64(0), s.int64(1), s.int64(2), s.real(3), s.real(4)});
    return out;
}

std::vector<FrameCountersRow> read_frame_counters(Database& db, std::int64_t run, bool fastest,
                                                  const std::vector<std::string>& columns) {
    // `fastest`: the counters are the same in every repetition (the same recording on a fresh
    // structure), min() only picks one of them.
    std::string sql = "SELECT config.structure, config.params, cell.scene_id, cell.config_id, frame.frame, ";
    sql += fastest ? "min(frame.rays), min(frame.raycast_ns), min(frame.update_ns)"
                   : "frame.rays, frame.raycast_ns, frame.update_ns";
    for (const std::string& c : columns) sql += fastest ? ", min(" + c + ")" : ", " + c;
    sql +=
        " FROM frame JOIN cell ON cell.id = frame.cell_id JOIN config ON config.id = cell.config_id "
        "WHERE cell.run_id IN " +
        run_group() + " AND frame.warmup = 0";
    sql += fastest ? " GROUP BY cell.scene_id, cell.config_id, frame.frame ORDER BY min(cell.id), frame.frame"
                   : " ORDER BY cell.id, frame.frame";
    Statement s = prepare_for_run(db, sql, run);
    std::vector<FrameCountersRow> out;
    while (s.step()) {
        FrameCountersRow r{s.text(0), s.text(1), s.int64(2), s.int64(3), s.int64(4),
                           s.real(5), s.real(6), s.real(7),  {}};
        r.counters.reserve(columns.size());
        for (std::size_t i = 0; i < columns.size(); ++i)  // NULL: not recorded (NaN, never 0)
            r.counters.push_back(s.is_null(8 + int(i)) ? NAN : s.real(8 + int(i)));
        out.push_back(std::move(r));
    }
    return out;
}

std::vector<std::pair<std::int64_t, std::int64_t>> read_measured_frame_keys(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(db,
                                  "SELECT frame.cell_id, frame.frame FROM frame JOIN cell ON cell.id = "
                                  "frame.cell_id WHERE cell.run_id IN " +
                                      run_group() + " AND frame.warmup = 0 ORDER BY cell.id, frame.frame",
                                  run);
    std::vector<std::pair<std::int64_t, std::int64_t>> out;
    while (s.step()) out.emplace_back(s.int64(0), s.int64(1));
    return out;
}

std::vector<FrameKindRow> read_frame_kinds(Database& db, std::int64_t run) {
    std::string sql =
        "SELECT frame_kind.cell_id, frame_kind.frame, frame_kind.kind, frame_kind.rays, frame_kind.raycast_ns";
    for (const CounterField& c : kCounterFields) sql += std::string(", frame_kind.") + c.name;
    sql +=
        " FROM frame_kind JOIN frame USING (cell_id, frame) JOIN cell ON cell.id = frame_kind.cell_id "
        "WHERE frame.warmup = 0 AND cell.run_id IN " +
        run_group();
    Statement s = prepare_for_run(db, sql, run);
    std::vector<FrameKindRow> out;
    while (s.step()) {
        FrameKindRow r{s.int64(0), s.int64(1), s.text(2), s.real(3), s.real(4), {}};
        for (int i = 0; i < int(kCounterFields.size()); ++i) r.counters.push_back(s.real(5 + i));
        out.push_back(std::move(r));
    }
    return out;
}

bool run_has_frame_kinds(Database& db, std::int64_t run) {
    Statement s =
        prepare_for_run(db,
                        "SELECT 1 FROM frame_kind JOIN cell ON cell.id = frame_kind.cell_id WHERE cell.run_id IN " +
                            run_group() + " LIMIT 1",
                        run);
    return s.step();
}

std::vector<FrameChangesRow> read_scene_changes(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(db,
                                  "SELECT " + scene_label() +
                                      ", scene.objects, frame.inserts + frame.removes + frame.moves FROM frame JOIN "
                                      "cell ON cell.id = frame.cell_id JOIN scene ON scene.id = cell.scene_id WHERE "
                                      "cell.id IN (SELECT min(id) FROM cell WHERE run_id IN " +
                                      run_group() + " GROUP BY scene_id) ORDER BY cell.id, frame.frame",
                                  run);
    std::vector<FrameChangesRow> out;
    while (s.step()) out.push_back({s.text(0), s.real(1), s.real(2)});
    return out;
}

// ---------------------------------------------------------------------------------------------
// Scenes, calibration, fits

std::vector<RunSceneRow> read_run_scenes(Database& db, std::int64_t run) {
    Statement s = prepare_for_run(db,
                                  "SELECT DISTINCT scene.id, " + scene_label() +
                                      ", scene.spec FROM cell JOIN scene ON scene.id = cell.scene_id WHERE "
                                      "cell.run_id IN " +
                                      run_group() + " ORDER BY scene.id",
                                  run);
    std::vector<RunSceneRow> out;
    while (s.step()) out.push_back({s.int64(0), s.text(1), s.text(2)});
    return out;
}

std::optional<std::pair<std::string, std::string>> read_scene_label(Database& db, std::int64_t scene_id) {
    Statement s = db.prepare("SELECT " + scene_label() + ", scene.spec FROM scene WHERE id = ?");
    s.bind(1, scene_id);
    if (!s.step()) return std::nullopt;
    return std::make_pair(s.text(0), s.text(1));
}

std::vector<std::string> read_calibrated_structures(Database& db, std::int64_t run) {
    Statement s = db.prepare("SELECT DISTINCT structure FROM calibration WHERE run_id = ? ORDER BY structure");
    s.bind(1, run);
    std::vector<std::string> out;
    while (s.step()) out.push_back(s.text(0));
    return out;
}

std::map<std::string, double> read_fit_coefficients(Database& db, std::int64_t run, const std::string& target,
                                                    const std::string& model, const std::string& coefficient) {
    Statement s = db.prepare(
        "SELECT fit.structure, fit_coefficient.value FROM fit JOIN fit_coefficient ON fit_coefficient.fit_id = fit.id "
        "WHERE fit.run_id = ? AND fit.target = ? AND fit.model = ? AND fit.status = 'ok' AND fit_coefficient.name = ?");
    s.bind_all(run, target, model, coefficient);
    std::map<std::string, double> out;
    while (s.step()) out[s.text(0)] = s.real(1);
    return out;
}

}  // namespace rcb
