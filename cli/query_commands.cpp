// rcbench query | compare | merge: reading, comparing and combining results databases.
#include <cmath>
#include <iostream>
#include <map>
#include <memory>

#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "core/base/output_file.h"
#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/run_ref.h"
#include "core/base/statistics.h"
#include "runner/compare.h"
#include "runner/decisions.h"
#include "runner/merge.h"
#include "runner/query.h"
#include "runner/store.h"
#include "cli/table.h"

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
    QueryResult result = read_only_query(*db, sql);
    if (csv) {
        auto line = [](const std::vector<std::string>& r) {
            std::string l;
            for (std::size_t i = 0; i < r.size(); ++i) l += (i ? "," : "") + csv_field(r[i]);
            return l;
        };
        std::cout << line(result.columns) << '\n';
        for (const auto& r : result.rows) std::cout << line(r) << '\n';
        return;
    }
    TextTable t(result.columns);
    for (auto& r : result.rows) t.add(std::move(r));
    t.print(std::cout);
}

/// How far two runs of one experiment are apart, per metric: |candidate − baseline| / their mean
/// over the scene × configuration cells, median, 90th percentile and worst (two runs of one
/// experiment on one machine: the repeatability docs/architecture.md reports).
void print_run_difference(const std::vector<Comparison>& rows) {
    for (const std::string metric : {"raycast", "update"}) {
        std::vector<double> d;
        for (const Comparison& r : rows) {
            const double mean = 0.5 * (r.baseline_median + r.candidate_median);
            if (r.metric == metric && mean > 0) d.push_back(std::abs(r.candidate_median - r.baseline_median) / mean);
        }
        if (d.empty()) continue;
        std::cout << metric << ": per-cell difference |candidate - baseline| / mean over " << d.size() << " cells: p50 "
                  << fixed(100 * quantile(d, 0.5), 1) << "%, p90 " << fixed(100 * quantile(d, 0.9), 1) << "%, worst "
                  << fixed(100 * quantile(d, 1.0), 1) << "%\n";
    }
}

/// "12.3%" for a gap; "-" where the picks agree.
std::string gap_text(const Decision& d, double gap) { return d.verdict == "same" ? "-" : fixed(100 * gap, 1) + "%"; }

void print_decision_table(const std::vector<Decision>& rows, bool per_structure, const std::string& a,
                          const std::string& b) {
    std::vector<std::string> header{"scene"};
    if (per_structure) header.push_back("structure");
    for (const std::string& h :
         std::vector<std::string>{"of", "best in " + a, "best in " + b, "verdict", "gap in " + a, "gap in " + b})
        header.push_back(h);
    TextTable t(header);
    for (const Decision& d : rows) {
        std::vector<std::string> row{d.scene};
        if (per_structure) row.push_back(d.structure);
        for (const std::string& v : std::vector<std::string>{std::to_string(d.candidates), d.pick_a, d.pick_b,
                                                             d.verdict, gap_text(d, d.gap_a), gap_text(d, d.gap_b)})
            row.push_back(v);
        t.add(std::move(row));
    }
    t.print(std::cout);
}

/// "best structure: 11 of 12 scenes agree, 12 of 12 agree or tie".
std::string agreement_line(const std::vector<Decision>& rows, const std::string& what, const std::string& over) {
    const auto [same, same_or_tie] = agreement(rows);
    return what + ": " + std::to_string(same) + " of " + std::to_string(rows.size()) + " " + over + " agree, " +
           std::to_string(same_or_tie) + " of " + std::to_string(rows.size()) + " agree or tie";
}

const char* const kDecisionReading =
    "per-frame time = update + ray cast: the median over frames of each frame's fastest ray cast over the "
    "cell's repetitions, plus the median over frames of each frame's median update (fit's default reading, "
    "fastest-cast)";

void print_decisions(const Decisions& d, const std::string& a, const std::string& b) {
    std::cout << "Decisions of A = " << a << " and B = " << b << " over the " << d.shared_cells
              << " (scene, configuration) cells both measured; " << kDecisionReading << ". tie: the picks differ "
              << "but each run's data put the other's pick within " << fixed(100 * d.tie, 1)
              << "% of its own; gap: how much slower the other run's pick is in this run's data\n\n";
    std::cout << "Best structure per scene (its best configuration's time):\n";
    print_decision_table(d.structures, false, "A", "B");
    std::cout << "\nBest configuration per (scene, structure):\n";
    print_decision_table(d.configurations, true, "A", "B");
    std::cout << '\n'
              << agreement_line(d.structures, "best structure", "scenes") << '\n'
              << agreement_line(d.configurations, "best configuration", "(scene, structure)") << '\n';
}

nlohmann::json decisions_json(const Decisions& d, const std::string& a, const std::string& b) {
    const auto part = [](const std::vector<Decision>& rows) {
        nlohmann::json list = nlohmann::json::array();
        for (const Decision& x : rows) {
            nlohmann::json row{{"scene", x.scene},   {"candidates", x.candidates}, {"best_a", x.pick_a},
                               {"best_b", x.pick_b}, {"verdict", x.verdict},       {"gap_a", x.gap_a},
                               {"gap_b", x.gap_b}};
            if (!x.structure.empty()) row["structure"] = x.structure;
            list.push_back(std::move(row));
        }
        const auto [same, same_or_tie] = agreement(rows);
        return nlohmann::json{
            {"decisions", rows.size()}, {"agree", same}, {"agree_or_tie", same_or_tie}, {"rows", list}};
    };
    return {{"a", a},
            {"b", b},
            {"reading", kDecisionReading},
            {"tie", d.tie},
            {"shared_cells", d.shared_cells},
            {"best_structure", part(d.structures)},
            {"best_configuration", part(d.configurations)}};
}

/// compare --decisions A.db[:RUN] B.db[:RUN].
void run_decisions(const std::vector<std::string>& refs, double tie, bool json) {
    const RunRef a = parse_run_ref("--decisions", refs[0]), b = parse_run_ref("--decisions", refs[1]);
    auto db_a = naming(a, [&] { return open_read_only(a.path); });
    auto db_b = naming(b, [&] { return open_read_only(b.path); });
    const std::int64_t run_a = resolve_ref(*db_a, a), run_b = resolve_ref(*db_b, b);
    if (run_a == run_b && same_file(a.path, b.path))
        throw InputError("--decisions " + a.text + " " + b.text +
                         ": both name the same run; give DB:RUN for two different runs");
    const std::string name_a = a.path + ":" + std::to_string(run_a), name_b = b.path + ":" + std::to_string(run_b);
    const Decisions d = compare_decisions(*db_a, run_a, *db_b, run_b, tie);
    if (json)
        std::cout << decisions_json(d, name_a, name_b).dump(2) << '\n';
    else
        print_decisions(d, name_a, name_b);
}

void add_compare_command(CLI::App& app) {
    struct CompareOptions {
        std::string db, baseline, candidate;
        std::string metric = "raycast";
        double alpha = 0.05;
        double fail_pct = -1;
        std::vector<std::string> decisions;
        double tie_pct = 5;
        bool json = false;
    };
    auto c = std::make_shared<CompareOptions>();
    CLI::App* compare = app.add_subcommand(
        "compare",
        "Compare two runs per scene and configuration, or (--decisions) the choices they make\n"
        "Compare two runs per scene and configuration: ratio of median frame times, Mann-Whitney U p-value, verdict; "
        "or, with --decisions, whether two runs pick the same best structure per scene and the same best "
        "configuration per (scene, structure)");
    CLI::Option* db =
        compare->add_option("db", c->db, "Results database (with --baseline and --candidate)")->check(input_file());
    CLI::Option* baseline = compare->add_option("--baseline", c->baseline, "Run id or git commit prefix");
    CLI::Option* candidate = compare->add_option("--candidate", c->candidate, "Run id or git commit prefix");
    CLI::Option* metric = compare->add_option("--metric", c->metric, "raycast, update or both")
                              ->capture_default_str()
                              ->check(CLI::IsMember({"raycast", "update", "both"}));
    CLI::Option* alpha = compare->add_option("--alpha", c->alpha, "Significance level of the U test")
                             ->capture_default_str()
                             ->check(finite_range(1e-9, 0.5));
    CLI::Option* fail = compare
                            ->add_option("--fail-on-regression", c->fail_pct,
                                         "Exit 1 when a significant slowdown exceeds this many percent")
                            ->check(finite_range(0.0, 1e6));
    CLI::Option* decisions =
        compare
            ->add_option("--decisions", c->decisions,
                         "A.db[:RUN] B.db[:RUN]: the best structure per scene and the best configuration per "
                         "(scene, structure) in each run (per-frame time, update + ray cast, fit's default "
                         "reading), the share that agree or tie, and the gap in each run's data where they differ; "
                         "a database without :RUN stands for its newest run with cells")
            ->expected(2);
    for (CLI::Option* o : {db, baseline, candidate, metric, alpha, fail}) decisions->excludes(o);
    compare
        ->add_option("--tie", c->tie_pct,
                     "With --decisions: picks within this many percent of each other in both runs' data tie")
        ->capture_default_str()
        ->check(finite_range(0.0, 100.0))
        ->needs(decisions);
    compare->add_flag("--json", c->json, "With --decisions: print JSON")->needs(decisions);
    compare->callback([c, db_option = db, baseline, candidate] {
        if (!c->decisions.empty()) return run_decisions(c->decisions, c->tie_pct / 100, c->json);
        for (const auto& [o, name] :
             {std::pair{db_option, "db"}, std::pair{baseline, "--baseline"}, std::pair{candidate, "--candidate"}})
            if (o->count() == 0)
                throw InputError(std::string("compare: ") + name +
                                 " is required (or compare two runs' decisions: --decisions A.db B.db)");
        auto db = open_read_only(c->db);
        const std::vector<Comparison> rows = compare_runs(*db, c->baseline, c->candidate, c->metric, c->alpha);
        // Runs of two programs (rcbench and one linking rcbench::cli with its own structures): the
        // rows are the structures both ran, each built into both programs.
        const std::vector<std::string> base_by = run_binaries(*db, c->baseline),
                                       cand_by = run_binaries(*db, c->candidate);
        if (base_by != cand_by)
            std::cout << "Baseline by " << join(base_by) << ", candidate by " << join(cand_by)
                      << ": the rows are the configurations both measured.\n";
        TextTable t({"scene", "structure", "params", "metric", "baseline ms", "candidate ms", "ratio", "p", "verdict",
                     "slow cells"});
        std::size_t regressions = 0;
        for (const Comparison& r : rows) {
            t.add({r.scene, r.structure, r.params, r.metric, fixed(r.baseline_median / 1e6, 4),
                   fixed(r.candidate_median / 1e6, 4), fixed(r.ratio, 3),
                   std::isnan(r.p_value) ? "-" : fixed(r.p_value, 4), r.verdict,
                   r.baseline_slow + r.candidate_slow == 0
                       ? ""
                       : std::to_string(r.baseline_slow) + "/" + std::to_string(r.candidate_slow)});
            if (c->fail_pct >= 0 && r.verdict == "slower" && (r.ratio - 1) * 100 > c->fail_pct) ++regressions;
        }
        t.print(std::cout);
        print_run_difference(rows);
        if (regressions)
            throw std::runtime_error(std::to_string(regressions) + " significant slowdowns above " +
                                     fixed(c->fail_pct, 1) + "%");
    });
}

}  // namespace

void add_query_commands(CLI::App& app) {
    struct QueryOptions {
        std::string db, sql;
        bool csv = false;
    };
    auto q = std::make_shared<QueryOptions>();
    CLI::App* query =
        app.add_subcommand("query", "Run a read-only SQL statement on a results database (schema: docs/database.md)");
    query->add_option("db", q->db, "Results database")->required()->check(input_file());
    query->add_option("sql", q->sql, "SQL, e.g. \"" + std::string(kQueryExample) + "\"")->required();
    query->add_flag("--csv", q->csv, "Print CSV instead of a table");
    query->callback([q] { run_query(q->db, q->sql, q->csv); });

    add_compare_command(app);

    struct MergeOptions {
        std::string out;
        std::vector<std::string> in;
    };
    auto m = std::make_shared<MergeOptions>();
    CLI::App* merge = app.add_subcommand(
        "merge",
        "Combine results databases (e.g. shards) into one\n"
        "Combine results databases (e.g. shards) into one; runs already present are skipped. Measurements "
        "are copied; fits, validations, tunings and derived categories are not (they describe the input's "
        "cells alone): fit the merged runs again");
    merge->add_option("out", m->out, "Database to merge into (created if missing)")->required();
    merge->add_option("in", m->in, "Databases to merge from")->required()->check(input_file());
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
            std::cout << m->in[i] << ": " << n.runs << " new runs, " << n.cells << " new cells merged";
            if (n.analyses > 0)
                std::cout << "; its " << n.analyses
                          << " fits, validations and derived categories are not copied (they describe its cells "
                             "alone): rcbench fit "
                          << m->out << " --run ID for each merged run";
            std::cout << '\n';
        }
    });
}

}  // namespace rcb
