#include "runner/merge.h"

#include <algorithm>
#include <map>
#include <optional>
#include <string>

#include "core/base/error.h"

namespace rcb {
namespace {

template <class... Keys>
std::int64_t id_of(Database& db, const std::string& select, const Keys&... keys) {
    Statement s = db.prepare(select);
    s.bind_all(keys...);
    s.step();
    return s.int64(0);
}

/// A merge copies rows as the input's pages give them: damaged pages can give rows its own
/// constraints forbid (a frame twice) or lose rows. SQLite's integrity check reads every page
/// and index first, so such an input is refused as a whole, naming it.
void check_integrity(Database& in) {
    Statement s = in.prepare("PRAGMA integrity_check(1)");
    std::string first = s.step() ? s.text(0) : std::string("no answer");
    std::replace(first.begin(), first.end(), '\n', ' ');  // SQLite's report spans lines
    if (first != "ok") throw InputError(in.path() + ": damaged results database (integrity check: " + first + ")");
}

/// The calibration passes of the input's run `from` that the output's run `to` lacks (a run merged
/// before it finished gains the passes made since).
void merge_calibration(Database& o, Database& in, std::int64_t from, std::int64_t to) {
    Statement cal = in.prepare(
        "SELECT structure, params, scene, rays, n_rb, n_t, ns_per_ray, mad, n_mp, n_miss, n_tp, pass, n_dup, repeats, "
        "cut FROM calibration "
        "WHERE run_id = ? ORDER BY rowid");
    cal.bind_all(from);
    Statement insert = o.prepare(
        "INSERT INTO calibration(run_id, structure, params, scene, rays, n_rb, n_t, ns_per_ray, mad, n_mp, n_miss, "
        "n_tp, pass, n_dup, repeats, cut) SELECT ?1,?2,?3,?4,?5,?6,?7,?8,?9,?10,?11,?12,?13,?14,?15,?16 WHERE NOT "
        "EXISTS (SELECT 1 FROM calibration "
        "WHERE run_id = ?1 AND structure = ?2 AND scene = ?4 AND pass = ?13)");
    while (cal.step()) {
        insert.reset();
        insert
            .bind_all(to, cal.text(0), cal.text(1), cal.text(2), cal.int64(3), cal.real(4), cal.real(5), cal.real(6),
                      cal.real(7), cal.real(8), cal.real(9), cal.real(10), cal.int64(11), cal.real(12), cal.int64(13),
                      cal.int64(14))
            .run();
    }
}

/// The output's id of the input's run `runs` (a row of the run query below): the run with the same
/// uuid, its finish time and calibration passes brought over; or a new run with the input's
/// experiment, machine and calibration. Counts a new run.
std::int64_t merge_run(Database& o, Database& in, Statement& runs, MergeCount& count) {
    {
        Statement existing = o.prepare("SELECT id FROM run WHERE uuid = ?");
        existing.bind(1, runs.text(1));
        if (existing.step()) {
            const std::int64_t run = existing.int64(0);
            if (!runs.is_null(7))
                o.prepare("UPDATE run SET finished_at = ? WHERE id = ? AND finished_at IS NULL")
                    .bind_all(runs.text(7), run)
                    .run();
            merge_calibration(o, in, runs.int64(0), run);
            return run;
        }
    }
    o.prepare("INSERT INTO experiment(name, description) VALUES (?, ?) ON CONFLICT(name) DO NOTHING")
        .bind_all(runs.text(2), runs.text(3))
        .run();
    const std::int64_t experiment = id_of(o, "SELECT id FROM experiment WHERE name = ?", runs.text(2));
    Statement insert_run = o.prepare(
        "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, finished_at, "
        "git_commit, compiler, flags, cpu_model, cores, governor, hostname, threads, shard, binary, binary_id) VALUES "
        "(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
    insert_run.bind_all(runs.text(1), experiment, runs.text(4), runs.text(5), runs.text(6));
    if (runs.is_null(7))
        insert_run.bind_null(6);
    else
        insert_run.bind(6, runs.text(7));
    insert_run.bind(7, runs.text(8)).bind(8, runs.text(9)).bind(9, runs.text(10)).bind(10, runs.text(11));
    insert_run.bind(11, runs.int64(12)).bind(12, runs.text(13)).bind(13, runs.text(14)).bind(14, runs.int64(15));
    insert_run.bind(15, runs.text(16)).bind(16, runs.text(17)).bind(17, runs.text(18));
    insert_run.run();
    const std::int64_t run = o.last_insert_id();
    ++count.runs;
    // The run's machine (cache sizes, calibration) travels with it: the fit's priors need it.
    Statement caches = in.prepare("SELECT level, type, size_bytes FROM run_cache WHERE run_id = ?");
    caches.bind_all(runs.int64(0));
    while (caches.step())
        o.prepare("INSERT INTO run_cache(run_id, level, type, size_bytes) VALUES (?,?,?,?)")
            .bind_all(run, caches.int64(0), caches.text(1), caches.int64(2))
            .run();
    merge_calibration(o, in, runs.int64(0), run);
    return run;
}

/// The output's ids of a cell's scene (with its features) and configuration, added when new.
std::pair<std::int64_t, std::int64_t> merge_scene_and_config(Database& o, Database& in, Statement& cells) {
    o.prepare(
         "INSERT INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) VALUES "
         "(?,?,?,?,?,?,?,?) ON CONFLICT(hash) DO NOTHING")
        .bind_all(cells.text(3), cells.text(4), cells.text(5), cells.text(6), cells.int64(7), cells.int64(8),
                  cells.real(9), cells.text(10))
        .run();
    const std::int64_t scene = id_of(o, "SELECT id FROM scene WHERE hash = ?", cells.text(3));
    if (!stored_scene_features(o, scene))  // features travel with their scene
        if (const auto f = stored_scene_features(in, cells.int64(2))) store_scene_features(o, scene, *f);
    o.prepare("INSERT INTO config(structure, params) VALUES (?, ?) ON CONFLICT DO NOTHING")
        .bind_all(cells.text(12), cells.text(13))
        .run();
    const std::int64_t config =
        id_of(o, "SELECT id FROM config WHERE structure = ? AND params = ?", cells.text(12), cells.text(13));
    return {scene, config};
}

/// A nullable REAL column.
std::optional<double> optional_real(const Statement& s, int column) {
    if (s.is_null(column)) return std::nullopt;
    return s.real(column);
}

/// Copies the frames (with their per-kind rows) and the machine state of the input's cell `from` to the output's cell
/// `to`.
void merge_frames(Database& o, Database& in, std::int64_t from, std::int64_t to) {
    Statement frames = in.prepare(
        "SELECT frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, hits, missed, extra, duplicate, "
        "n_t, n_rb, n_tp, memory_bytes, sah_cost, stats, returned, correct, relevant, n_ro, n_ro_hits, n_th, n_mp, "
        "n_miss, update_wall_ns, raycast_wall_ns, writes, n_dup, update_work FROM frame WHERE cell_id = ? ORDER BY "
        "frame");
    frames.bind(1, from);
    Statement insert_frame = o.prepare(
        "INSERT INTO frame(cell_id, frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, hits, "
        "missed, extra, duplicate, n_t, n_rb, n_tp, memory_bytes, sah_cost, stats, returned, correct, relevant, n_ro, "
        "n_ro_hits, n_th, n_mp, n_miss, update_wall_ns, raycast_wall_ns, writes, n_dup, update_work) "
        "VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
    while (frames.step()) {
        insert_frame.bind(1, to);
        for (int c = 0; c < 16; ++c) insert_frame.bind(c + 2, frames.int64(c));
        if (frames.is_null(16))
            insert_frame.bind_null(18);
        else
            insert_frame.bind(18, frames.real(16));
        insert_frame.bind(19, frames.text(17));
        for (int c = 18; c < 26; ++c) insert_frame.bind(c + 2, frames.int64(c));
        for (int c = 26; c < 28; ++c)  // NULL in frames stored before the wall times were kept
            frames.is_null(c) ? insert_frame.bind_null(c + 2) : insert_frame.bind(c + 2, frames.int64(c));
        insert_frame.bind(30, frames.int64(28));
        insert_frame.bind(31, frames.int64(29));
        // NULL in frames stored before the update's work was counted
        frames.is_null(30) ? insert_frame.bind_null(32) : insert_frame.bind(32, frames.int64(30));
        insert_frame.run();
    }
    Statement kinds = in.prepare(
        "SELECT frame, kind, rays, raycast_ns, raycast_wall_ns, hits, n_t, n_rb, n_tp, n_ro, n_ro_hits, n_th, n_mp, "
        "n_miss, n_dup FROM frame_kind WHERE cell_id = ?");
    kinds.bind(1, from);
    Statement insert_kind = o.prepare(kFrameKindInsertSql);
    while (kinds.step()) {
        insert_kind.bind(1, to).bind(2, kinds.int64(0)).bind(3, kinds.text(1));
        for (int c = 2; c < 15; ++c) insert_kind.bind(c + 2, kinds.int64(c));
        insert_kind.run();
    }
    Statement state =
        in.prepare("SELECT load_1m, calibration_ns, slow, resampled, memory_ns FROM cell_state WHERE cell_id = ?");
    state.bind(1, from);
    if (state.step())
        o.prepare(
             "INSERT INTO cell_state(cell_id, load_1m, calibration_ns, slow, resampled, memory_ns) VALUES "
             "(?,?,?,?,?,?)")
            .bind_all(to, state.real(0), state.real(1), state.int64(2), state.int64(3), optional_real(state, 4))
            .run();
}

/// The input run's analyses a merge leaves behind (MergeCount::analyses).
std::size_t analyses_of(Database& in, std::int64_t in_run) {
    std::size_t n = 0;
    for (const char* table : {"fit", "model_validation", "derived_category", "scene_clustering"})
        n += std::size_t(id_of(in, std::string("SELECT count(*) FROM ") + table + " WHERE run_id = ?", in_run));
    return n;
}

/// Copies the cells of the input's run `in_run` that the output's run `run` does not have.
void merge_cells(Database& o, Database& in, std::int64_t in_run, std::int64_t run, MergeCount& count) {
    Statement cells = in.prepare(
        "SELECT cell.id, cell_key, scene.id, scene.hash, scene.name, scene.spec, scene.meta, scene.objects, "
        "scene.frames, scene.rays_per_frame, scene.stats, config.id, config.structure, config.params, repetition, "
        "finished_at, cell.objects, build_ns, memory_bytes, verified, mismatches, cell.frames, update_ns_median, "
        "update_ns_mad, raycast_ns_median, raycast_ns_mad, clock, update_ns_ci_low, update_ns_ci_high, "
        "raycast_ns_ci_low, raycast_ns_ci_high FROM cell JOIN scene ON scene.id = cell.scene_id "
        "JOIN config ON config.id = cell.config_id WHERE run_id = ? ORDER BY cell.id");
    cells.bind(1, in_run);
    while (cells.step()) {
        {
            Statement has = o.prepare("SELECT 1 FROM cell WHERE run_id = ? AND cell_key = ?");
            has.bind_all(run, cells.text(1));
            if (has.step()) continue;
        }
        const auto [scene, config] = merge_scene_and_config(o, in, cells);
        o.prepare(
             "INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, build_ns, "
             "memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, raycast_ns_median, "
             "raycast_ns_mad, clock, update_ns_ci_low, update_ns_ci_high, raycast_ns_ci_low, raycast_ns_ci_high) "
             "VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
            .bind_all(run, cells.text(1), scene, config, cells.int64(14), cells.text(15), cells.int64(16),
                      cells.int64(17), cells.int64(18), cells.int64(19), cells.int64(20), cells.int64(21),
                      cells.real(22), cells.real(23), cells.real(24), cells.real(25), cells.text(26),
                      optional_real(cells, 27), optional_real(cells, 28), optional_real(cells, 29),
                      optional_real(cells, 30))
            .run();
        merge_frames(o, in, cells.int64(0), o.last_insert_id());
        ++count.cells;
    }
}

}  // namespace

MergeCount merge_into(ResultStore& out, Database& in) {
    check_integrity(in);
    Database& o = out.db();
    Transaction t(o);
    MergeCount count;
    try {
        Statement runs = in.prepare(
            "SELECT run.id, run.uuid, experiment.name, experiment.description, experiment_hash, experiment_content, "
            "started_at, finished_at, git_commit, compiler, flags, cpu_model, cores, governor, hostname, threads, "
            "shard, binary, binary_id FROM run JOIN experiment ON experiment.id = run.experiment_id ORDER BY run.id");
        while (runs.step()) {
            const std::int64_t run = merge_run(o, in, runs, count);
            merge_cells(o, in, runs.int64(0), run, count);
            count.analyses += analyses_of(in, runs.int64(0));
            // The interval over repetitions follows the run's cells, old and new.
            store_cell_intervals(o, run);
        }
    } catch (const SqlError& e) {
        // The output was opened and its schema checked, and the input passed the integrity check:
        // rows the output's constraints refuse came so from the input.
        if ((e.code() & 0xff) != SQLITE_CONSTRAINT) throw;
        throw InputError(in.path() + ": cannot merge this results database (" + e.what() + ")");
    }
    t.commit();
    return count;
}

}  // namespace rcb
