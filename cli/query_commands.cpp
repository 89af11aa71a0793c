// rcbench query | compare | merge: reading, comparing and combining results databases.
#include <cmath>
#include <iostream>
#include <map>
#include <memory>

#include "core/error.h"
#include "core/output_file.h"
#include "runner/commands.h"
#include "runner/compare.h"
#include "runner/store.h"
#include "runner/table.h"

namespace rcb {
namespace {

std::string csv_field(const std::string& s) {
    if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
}

void run_query(const std::string& path, const std::string& sql, bool csv) {
    auto db = open_read_only(path);
    std::unique_ptr<Statement> s;
    try {
        s = std::make_unique<Statement>(db->prepare(sql));
    } catch (const SqlError& e) {
        throw InputError("query: " + std::string(e.what()));
    }
    if (!s->read_only()) throw InputError("query: only read-only statements are allowed (SELECT, WITH, PRAGMA reads)");
    std::vector<std::string> header;
    for (int i = 0; i < s->columns(); ++i) header.push_back(s->column_name(i));
    std::vector<std::vector<std::string>> rows;
    try {
        while (s->step()) {
            std::vector<std::string> row;
            for (int i = 0; i < s->columns(); ++i) row.push_back(s->is_null(i) ? "" : s->text(i));
            rows.push_back(std::move(row));
        }
    } catch (const SqlError& e) {
        throw InputError("query: " + std::string(e.what()));
    }
    if (csv) {
        auto line = [](const std::vector<std::string>& r) {
            std::string l;
            for (std::size_t i = 0; i < r.size(); ++i) l += (i ? "," : "") + csv_field(r[i]);
            return l;
        };
        std::cout << line(header) << '\n';
        for (const auto& r : rows) std::cout << line(r) << '\n';
        return;
    }
    TextTable t(header);
    for (auto& r : rows) t.add(std::move(r));
    t.print(std::cout);
}

struct MergeCount {
    std::size_t runs = 0;   ///< runs new to `out`
    std::size_t cells = 0;  ///< cells new to `out`, in new runs or in runs it had unfinished
};

/// Copies into `out` every run of `in` (matched by run uuid) and every cell of it that `out` does
/// not have yet, remapping ids; a run `out` holds unfinished gains the cells finished since and its
/// finish time. So merging a shard, resuming the shard and merging it again completes the run.
MergeCount merge_into(ResultStore& out, Database& in) {
    Database& o = out.db();
    Transaction t(o);
    MergeCount count;
    auto id_of = [&](const std::string& select, auto&&... keys) {
        Statement s = o.prepare(select);
        s.bind_all(keys...);
        s.step();
        return s.int64(0);
    };
    Statement runs = in.prepare(
        "SELECT run.id, run.uuid, experiment.name, experiment.description, experiment_hash, experiment_content, started_at, "
        "finished_at, git_commit, compiler, flags, cpu_model, cores, governor, hostname, threads, shard "
        "FROM run JOIN experiment ON experiment.id = run.experiment_id ORDER BY run.id");
    while (runs.step()) {
        std::int64_t run = 0;
        {
            Statement existing = o.prepare("SELECT id FROM run WHERE uuid = ?");
            existing.bind(1, runs.text(1));
            if (existing.step()) run = existing.int64(0);
        }
        if (run) {
            if (!runs.is_null(7))
                o.prepare("UPDATE run SET finished_at = ? WHERE id = ? AND finished_at IS NULL").bind_all(runs.text(7), run).run();
        } else {
            o.prepare("INSERT INTO experiment(name, description) VALUES (?, ?) ON CONFLICT(name) DO NOTHING")
                .bind_all(runs.text(2), runs.text(3))
                .run();
            const std::int64_t experiment = id_of("SELECT id FROM experiment WHERE name = ?", runs.text(2));
            Statement insert_run = o.prepare(
                "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, finished_at, git_commit, "
                "compiler, flags, cpu_model, cores, governor, hostname, threads, shard) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
            insert_run.bind_all(runs.text(1), experiment, runs.text(4), runs.text(5), runs.text(6));
            if (runs.is_null(7)) insert_run.bind_null(6);
            else insert_run.bind(6, runs.text(7));
            insert_run.bind(7, runs.text(8)).bind(8, runs.text(9)).bind(9, runs.text(10)).bind(10, runs.text(11));
            insert_run.bind(11, runs.int64(12)).bind(12, runs.text(13)).bind(13, runs.text(14)).bind(14, runs.int64(15));
            insert_run.bind(15, runs.text(16));
            insert_run.run();
            run = o.last_insert_id();
            ++count.runs;
        }

        Statement cells = in.prepare(
            "SELECT cell.id, cell_key, scene.id, scene.hash, scene.name, scene.spec, scene.meta, scene.objects, scene.frames, "
            "scene.rays_per_frame, scene.stats, config.id, config.structure, config.params, repetition, finished_at, "
            "cell.objects, build_ns, memory_bytes, verified, mismatches, cell.frames, update_ns_median, update_ns_mad, "
            "raycast_ns_median, raycast_ns_mad FROM cell JOIN scene ON scene.id = cell.scene_id "
            "JOIN config ON config.id = cell.config_id WHERE run_id = ?");
        cells.bind(1, runs.int64(0));
        while (cells.step()) {
            {
                Statement has = o.prepare("SELECT 1 FROM cell WHERE run_id = ? AND cell_key = ?");
                has.bind_all(run, cells.text(1));
                if (has.step()) continue;
            }
            o.prepare("INSERT INTO scene(hash, name, spec, meta, objects, frames, rays_per_frame, stats) VALUES (?,?,?,?,?,?,?,?) "
                      "ON CONFLICT(hash) DO NOTHING")
                .bind_all(cells.text(3), cells.text(4), cells.text(5), cells.text(6), cells.int64(7), cells.int64(8),
                          cells.real(9), cells.text(10))
                .run();
            const std::int64_t scene = id_of("SELECT id FROM scene WHERE hash = ?", cells.text(3));
            o.prepare("INSERT INTO config(structure, params) VALUES (?, ?) ON CONFLICT DO NOTHING")
                .bind_all(cells.text(12), cells.text(13))
                .run();
            const std::int64_t config = id_of("SELECT id FROM config WHERE structure = ? AND params = ?", cells.text(12), cells.text(13));
            o.prepare("INSERT INTO cell(run_id, cell_key, scene_id, config_id, repetition, finished_at, objects, build_ns, "
                      "memory_bytes, verified, mismatches, frames, update_ns_median, update_ns_mad, raycast_ns_median, "
                      "raycast_ns_mad) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
                .bind_all(run, cells.text(1), scene, config, cells.int64(14), cells.text(15), cells.int64(16), cells.int64(17),
                          cells.int64(18), cells.int64(19), cells.int64(20), cells.int64(21), cells.real(22), cells.real(23),
                          cells.real(24), cells.real(25))
                .run();
            const std::int64_t cell = o.last_insert_id();
            Statement frames = in.prepare(
                "SELECT frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, hits, missed, extra, duplicate, "
                "n_t, n_rb, n_tp, memory_bytes, sah_cost, stats FROM frame WHERE cell_id = ?");
            frames.bind(1, cells.int64(0));
            Statement insert_frame = o.prepare(
                "INSERT INTO frame(cell_id, frame, warmup, inserts, removes, moves, rays, update_ns, raycast_ns, hits, missed, "
                "extra, duplicate, n_t, n_rb, n_tp, memory_bytes, sah_cost, stats) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
            while (frames.step()) {
                insert_frame.bind(1, cell);
                for (int c = 0; c < 16; ++c) insert_frame.bind(c + 2, frames.int64(c));
                if (frames.is_null(16)) insert_frame.bind_null(18);
                else insert_frame.bind(18, frames.real(16));
                insert_frame.bind(19, frames.text(17));
                insert_frame.run();
            }
            ++count.cells;
        }
    }
    t.commit();
    return count;
}

}  // namespace

void add_query_commands(CLI::App& app) {
    struct QueryOptions {
        std::string db, sql;
        bool csv = false;
    };
    auto q = std::make_shared<QueryOptions>();
    CLI::App* query = app.add_subcommand("query", "Run a read-only SQL statement on a results database (schema: results/README.md)");
    query->add_option("db", q->db, "Results database")->required();
    query->add_option("sql", q->sql, "SQL, e.g. \"SELECT scene, structure, raycast_ns_median FROM cell_summary\"")->required();
    query->add_flag("--csv", q->csv, "Print CSV instead of a table");
    query->callback([q] { run_query(q->db, q->sql, q->csv); });

    struct CompareOptions {
        std::string db, baseline, candidate;
        std::string metric = "raycast";
        double alpha = 0.05;
        double fail_pct = -1;
    };
    auto c = std::make_shared<CompareOptions>();
    CLI::App* compare = app.add_subcommand(
        "compare", "Compare two runs per scene and configuration: ratio of median frame times, Mann-Whitney U p-value, verdict");
    compare->add_option("db", c->db, "Results database")->required();
    compare->add_option("--baseline", c->baseline, "Run id or git commit prefix")->required();
    compare->add_option("--candidate", c->candidate, "Run id or git commit prefix")->required();
    compare->add_option("--metric", c->metric, "raycast, update or both")->capture_default_str()->check(CLI::IsMember({"raycast", "update", "both"}));
    compare->add_option("--alpha", c->alpha, "Significance level of the U test")->capture_default_str()->check(CLI::Range(1e-9, 0.5));
    compare->add_option("--fail-on-regression", c->fail_pct, "Exit 1 when a significant slowdown exceeds this many percent")
        ->check(CLI::Range(0.0, 1e6));
    compare->callback([c] {
        auto db = open_read_only(c->db);
        const std::vector<Comparison> rows = compare_runs(*db, c->baseline, c->candidate, c->metric, c->alpha);
        TextTable t({"scene", "structure", "params", "metric", "baseline ms", "candidate ms", "ratio", "p", "verdict"});
        std::size_t regressions = 0;
        for (const Comparison& r : rows) {
            t.add({r.scene, r.structure, r.params, r.metric, fixed(r.baseline_median / 1e6, 4), fixed(r.candidate_median / 1e6, 4),
                   fixed(r.ratio, 3), std::isnan(r.p_value) ? "-" : fixed(r.p_value, 4), r.verdict});
            if (c->fail_pct >= 0 && r.verdict == "slower" && (r.ratio - 1) * 100 > c->fail_pct) ++regressions;
        }
        t.print(std::cout);
        if (regressions)
            throw std::runtime_error(std::to_string(regressions) + " significant slowdowns above " + fixed(c->fail_pct, 1) + "%");
    });

    struct MergeOptions {
        std::string out;
        std::vector<std::string> in;
    };
    auto m = std::make_shared<MergeOptions>();
    CLI::App* merge = app.add_subcommand("merge", "Combine results databases (e.g. shards) into one; runs already present are skipped");
    merge->add_option("out", m->out, "Database to merge into (created if missing)")->required();
    merge->add_option("in", m->in, "Databases to merge from")->required();
    merge->callback([m] {
        // Every input is opened (and so checked) before the output is created or touched.
        std::vector<std::unique_ptr<Database>> inputs;
        for (const std::string& in : m->in) {
            if (same_file(in, m->out)) throw InputError(in + ": cannot merge a database into itself");
            inputs.push_back(open_read_only(in));
        }
        ResultStore out(m->out);
        for (std::size_t i = 0; i < inputs.size(); ++i) {
            const MergeCount n = merge_into(out, *inputs[i]);
            std::cout << m->in[i] << ": " << n.runs << " new runs, " << n.cells << " new cells merged\n";
        }
    });
}

}  // namespace rcb
